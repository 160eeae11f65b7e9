#include "image/image.h"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <exception>
#include <filesystem>
#include <memory>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <png.h>
#include <stb_image.h>

#include "base/strings.h"

namespace previs {

namespace {

// A missing file or folder gets its own message: it is the most common mistake and the library
// messages for it are cryptic.
Status checkReadable(const std::string& path) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec))
        return makeError("cannot read image '{}': no such file (check the path)", path);
    if (std::filesystem::is_directory(path, ec))
        return makeError("cannot read image '{}': it is a folder, not an image file", path);
    return {};
}

Status checkWritableFolder(const std::string& path) {
    std::filesystem::path parent = std::filesystem::path(path).parent_path();
    if (parent.empty()) parent = ".";
    std::error_code ec;
    if (!std::filesystem::is_directory(parent, ec))
        return makeError("cannot write image '{}': folder '{}' does not exist (create it first)",
                         path, parent.string());
    return {};
}

Result<ImageF> readExr(const std::string& path) {
    try {
        Imf::InputFile file(path.c_str());
        const Imf::Header& header = file.header();
        const Imath::Box2i dw = header.dataWindow();
        const int64_t w = int64_t(dw.max.x) - dw.min.x + 1;
        const int64_t h = int64_t(dw.max.y) - dw.min.y + 1;
        if (w <= 0 || h <= 0 || w > 65536 || h > 65536)
            return makeError("cannot read image '{}': unsupported EXR size {}x{}", path, w, h);

        const Imf::ChannelList& channels = header.channels();
        std::vector<const char*> names;
        if (channels.findChannel("R") && channels.findChannel("G") && channels.findChannel("B")) {
            names = {"R", "G", "B"};
            if (channels.findChannel("A")) names.push_back("A");
        } else if (channels.findChannel("Y")) {
            names = {"Y"};
        } else if (channels.findChannel("R")) {
            names = {"R"};
        } else {
            return makeError(
                "cannot read image '{}': no R,G,B or Y channel (multi-layer EXRs need the "
                "beauty pass in the default layer)",
                path);
        }

        ImageF image;
        image.width = uint32_t(w);
        image.height = uint32_t(h);
        image.channels = uint32_t(names.size());
        image.pixels.assign(size_t(w) * size_t(h) * names.size(), 0.0f);

        Imf::FrameBuffer frameBuffer;
        const size_t xStride = sizeof(float) * names.size();
        const size_t yStride = xStride * size_t(w);
        for (size_t c = 0; c < names.size(); ++c) {
            // Slice::Make offsets the base pointer by the data window origin for us.
            frameBuffer.insert(names[c],
                               Imf::Slice::Make(Imf::FLOAT, image.pixels.data() + c, dw, xStride,
                                                yStride));
        }
        file.setFrameBuffer(frameBuffer);
        file.readPixels(dw.min.y, dw.max.y);
        return image;
    } catch (const std::exception& e) {
        return makeError("cannot read EXR image '{}': {}", path, e.what());
    }
}

Result<ImageF> readStb(const std::string& path, bool hdr) {
    int w = 0;
    int h = 0;
    int n = 0;
    ImageF image;
    if (hdr) {
        std::unique_ptr<float, decltype(&stbi_image_free)> data(
            stbi_loadf(path.c_str(), &w, &h, &n, 3), &stbi_image_free);
        if (!data)
            return makeError("cannot decode Radiance HDR image '{}': {}", path,
                             stbi_failure_reason() ? stbi_failure_reason() : "unknown error");
        image.channels = 3;
        image.pixels.assign(data.get(), data.get() + size_t(w) * size_t(h) * 3);
    } else {
        std::unique_ptr<unsigned char, decltype(&stbi_image_free)> data(
            stbi_load(path.c_str(), &w, &h, &n, 0), &stbi_image_free);
        if (!data)
            return makeError("cannot decode image '{}': {} (is it a valid PNG/JPEG?)", path,
                             stbi_failure_reason() ? stbi_failure_reason() : "unknown error");
        // Grey+alpha becomes RGBA so callers see 1, 3 or 4 channels only.
        const int outChannels = n == 2 ? 4 : n;
        image.channels = uint32_t(outChannels);
        image.ldrSrgb = true;
        image.pixels.resize(size_t(w) * size_t(h) * size_t(outChannels));
        for (size_t p = 0; p < size_t(w) * size_t(h); ++p) {
            const unsigned char* src = data.get() + p * size_t(n);
            float* dst = image.pixels.data() + p * size_t(outChannels);
            if (n == 2) {
                dst[0] = dst[1] = dst[2] = src[0] / 255.0f;
                dst[3] = src[1] / 255.0f;
            } else {
                for (int c = 0; c < n; ++c) dst[c] = src[c] / 255.0f;
            }
        }
    }
    image.width = uint32_t(w);
    image.height = uint32_t(h);
    return image;
}

}  // namespace

Result<ImageF> readImage(const std::string& path) {
    if (Status s = checkReadable(path); !s) return s.error();
    const std::string ext = lowerExtension(path);
    if (ext == ".exr") return readExr(path);
    if (ext == ".hdr") return readStb(path, true);
    if (ext == ".png" || ext == ".jpg" || ext == ".jpeg") return readStb(path, false);
    return makeError(
        "cannot read image '{}': unsupported extension '{}' (use .exr, .hdr, .png, .jpg)", path,
        ext);
}

Status writeExr(const std::string& path, const ImageF& image) {
    if (lowerExtension(path) != ".exr")
        return makeError("cannot write EXR image '{}': the file name must end in .exr", path);
    if (image.width == 0 || image.height == 0 ||
        image.pixels.size() != size_t(image.width) * image.height * image.channels)
        return makeError("cannot write EXR image '{}': image is empty or its size is inconsistent",
                         path);
    std::vector<const char*> names;
    switch (image.channels) {
        case 1: names = {"Y"}; break;
        case 3: names = {"R", "G", "B"}; break;
        case 4: names = {"R", "G", "B", "A"}; break;
        default:
            return makeError("cannot write EXR image '{}': {} channels (use 1, 3 or 4)", path,
                             image.channels);
    }
    if (Status s = checkWritableFolder(path); !s) return s;
    try {
        Imf::Header header(int(image.width), int(image.height));
        header.compression() = Imf::ZIP_COMPRESSION;
        for (const char* name : names) header.channels().insert(name, Imf::Channel(Imf::FLOAT));
        Imf::FrameBuffer frameBuffer;
        const size_t xStride = sizeof(float) * image.channels;
        const size_t yStride = xStride * image.width;
        for (size_t c = 0; c < names.size(); ++c) {
            // OpenEXR only reads through this pointer; its API is not const-correct.
            char* base = reinterpret_cast<char*>(const_cast<float*>(image.pixels.data() + c));
            frameBuffer.insert(names[c], Imf::Slice(Imf::FLOAT, base, xStride, yStride));
        }
        Imf::OutputFile file(path.c_str(), header);
        file.setFrameBuffer(frameBuffer);
        file.writePixels(int(image.height));
    } catch (const std::exception& e) {
        return makeError("cannot write EXR image '{}': {} (check the folder is writable)", path,
                         e.what());
    }
    return {};
}

Status writePng(const std::string& path, uint32_t width, uint32_t height,
                const std::vector<uint8_t>& rgb8) {
    if (lowerExtension(path) != ".png")
        return makeError("cannot write PNG image '{}': the file name must end in .png", path);
    if (width == 0 || height == 0 || rgb8.size() != size_t(width) * height * 3)
        return makeError("cannot write PNG image '{}': {} bytes for {}x{} RGB (need {})", path,
                         rgb8.size(), width, height, size_t(width) * height * 3);
    if (Status s = checkWritableFolder(path); !s) return s;

    png_image png;
    std::memset(&png, 0, sizeof(png));
    png.version = PNG_IMAGE_VERSION;
    png.width = width;
    png.height = height;
    png.format = PNG_FORMAT_RGB;
    errno = 0;
    if (!png_image_write_to_file(&png, path.c_str(), 0, rgb8.data(), 0, nullptr)) {
        const std::string reason = errno ? std::strerror(errno) : png.message;
        png_image_free(&png);
        return makeError("cannot write PNG image '{}': {} (check the folder is writable)", path,
                         reason);
    }
    return {};
}

}  // namespace previs
