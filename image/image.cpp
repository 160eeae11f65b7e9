#include "image/image.h"

#include <OpenEXR/Iex.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfIO.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <png.h>
#include <stb_image.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string_view>

#include "base/bounded_file.h"
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

// Library messages may span lines; a user sees one.
std::string oneLine(std::string text) {
    std::replace(text.begin(), text.end(), '\n', ' ');
    return text;
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

// What a file's first bytes say it is. Formats we cannot read are named too, so a refusal can
// say what the file actually is.
enum class ContentType { Exr, Hdr, Png, Jpeg, Other };

struct Sniffed {
    ContentType type = ContentType::Other;
    const char* name = "";  // "a PNG image", ...
};

bool startsWith(std::span<const uint8_t> bytes, std::string_view magic) {
    return bytes.size() >= magic.size() &&
           std::memcmp(bytes.data(), magic.data(), magic.size()) == 0;
}

Sniffed sniff(std::span<const uint8_t> bytes) {
    using namespace std::string_view_literals;
    if (startsWith(bytes, "\x76\x2f\x31\x01"sv)) return {ContentType::Exr, "an OpenEXR image"};
    if (startsWith(bytes, "#?RADIANCE\n"sv) || startsWith(bytes, "#?RGBE\n"sv))
        return {ContentType::Hdr, "a Radiance HDR image"};
    if (startsWith(bytes, "\x89PNG\r\n\x1a\n"sv)) return {ContentType::Png, "a PNG image"};
    if (startsWith(bytes, "\xff\xd8\xff"sv)) return {ContentType::Jpeg, "a JPEG image"};
    struct Other {
        std::string_view magic;
        const char* name;
    };
    static const Other kOthers[] = {
        {"GIF8"sv, "a GIF image"},
        {"BM"sv, "a BMP image"},
        {"8BPS"sv, "a Photoshop image"},
        {"II*\0"sv, "a TIFF image"},
        {"MM\0*"sv, "a TIFF image"},
        {"glTF"sv, "a binary glTF file"},
        {"#?"sv, "a Radiance file without a valid first line"},
        {"\x1f\x8b"sv, "a gzip archive"},
        {"PK\x03\x04"sv, "a zip archive"},
    };
    for (const Other& o : kOthers)
        if (startsWith(bytes, o.magic)) return {ContentType::Other, o.name};
    if (bytes.size() >= 12 && startsWith(bytes, "RIFF"sv) &&
        std::memcmp(bytes.data() + 8, "WEBP", 4) == 0)
        return {ContentType::Other, "a WebP image"};
    if (bytes.empty()) return {ContentType::Other, "an empty file"};
    return {ContentType::Other, "not an image this reader knows"};
}

// A FIFO or a device is refused, never waited on, and the size is bounded before reading (base/
// bounded_file.h); links are followed: the operator names images, a take's are checked before.
Result<std::vector<uint8_t>> readFileBytes(const std::string& path, const ImageLimits& limits) {
    return readBoundedFile(path, limits.maxFileBytes, FileLinks::Follow, "image");
}

Status checkSize(const std::string& path, const char* format, int64_t w, int64_t h,
                 const ImageLimits& limits) {
    if (w <= 0 || h <= 0)
        return makeError("cannot read image '{}': its header says {}x{} pixels (corrupt file)",
                         path, w, h);
    if (w > int64_t(limits.maxWidth) || h > int64_t(limits.maxHeight))
        return makeError(
            "cannot read image '{}': {} is {}x{} pixels, larger than the limit {}x{} (scale it "
            "down)",
            path, format, w, h, limits.maxWidth, limits.maxHeight);
    return {};
}

// --- OpenEXR -------------------------------------------------------------------------------

// The data window from the first header (OpenEXR file layout: magic, version, then attributes
// `name\0 type\0 int32 size, value` up to an empty name), read before OpenEXR sees the file so
// the size limit holds before anything is allocated for it.
Result<std::array<int32_t, 4>> exrDataWindow(std::span<const uint8_t> bytes,
                                             const std::string& path) {
    size_t at = 8;
    auto cString = [&](std::string& out) {
        out.clear();
        while (at < bytes.size() && bytes[at] != 0 && out.size() < 256) out += char(bytes[at++]);
        if (at >= bytes.size() || bytes[at] != 0) return false;
        ++at;
        return true;
    };
    auto int32At = [&](size_t offset) {
        uint32_t v = 0;
        for (int i = 3; i >= 0; --i) v = (v << 8) | bytes[offset + size_t(i)];
        return int32_t(v);
    };
    std::string name;
    std::string type;
    while (cString(name) && !name.empty()) {  // an empty name ends the header
        if (!cString(type) || bytes.size() - at < 4) break;
        const int32_t size = int32At(at);
        at += 4;
        if (size < 0 || size_t(size) > bytes.size() - at) break;
        if (name == "dataWindow" && type == "box2i" && size == 16)
            return std::array<int32_t, 4>{int32At(at), int32At(at + 4), int32At(at + 8),
                                          int32At(at + 12)};
        at += size_t(size);
    }
    return makeError(
        "cannot read image '{}': the OpenEXR header is truncated or has no data "
        "window (corrupt file)",
        path);
}

// Lets OpenEXR read from the bytes already in memory; reading past the end throws, as reading
// a short file does.
class MemoryIStream : public Imf::IStream {
public:
    MemoryIStream(std::span<const uint8_t> bytes, const std::string& path)
        : Imf::IStream(path.c_str()), bytes_(bytes) {}
    bool read(char c[], int n) override {
        if (n < 0 || pos_ > bytes_.size() || uint64_t(n) > bytes_.size() - pos_)
            throw Iex::InputExc("unexpected end of file");
        std::memcpy(c, bytes_.data() + pos_, size_t(n));
        pos_ += uint64_t(n);
        return pos_ < bytes_.size();
    }
    uint64_t tellg() override { return pos_; }
    void seekg(uint64_t pos) override { pos_ = pos; }

private:
    std::span<const uint8_t> bytes_;
    uint64_t pos_ = 0;
};

Result<ImageF> readExr(std::span<const uint8_t> bytes, const std::string& path,
                       const ImageLimits& limits, const std::string& layer = {}) {
    Result<std::array<int32_t, 4>> window = exrDataWindow(bytes, path);
    if (!window) return window.error();
    const int64_t w = int64_t((*window)[2]) - (*window)[0] + 1;
    const int64_t h = int64_t((*window)[3]) - (*window)[1] + 1;
    if (Status s = checkSize(path, "the OpenEXR image", w, h, limits); !s) return s.error();
    try {
        MemoryIStream stream(bytes, path);
        Imf::InputFile file(stream);
        const Imf::Header& header = file.header();
        const Imath::Box2i dw = header.dataWindow();
        if (dw.min.x != (*window)[0] || dw.min.y != (*window)[1] || dw.max.x != (*window)[2] ||
            dw.max.y != (*window)[3])
            return makeError("cannot read image '{}': inconsistent OpenEXR header (corrupt file)",
                             path);

        const Imf::ChannelList& channels = header.channels();
        // A named layer's channels are "<layer>.R" ... (writeExrLayers' convention).
        const std::string prefix = layer.empty() ? std::string() : layer + ".";
        auto has = [&](const char* c) { return channels.findChannel(prefix + c) != nullptr; };
        std::vector<std::string> names;
        if (has("R") && has("G") && has("B")) {
            names = {prefix + "R", prefix + "G", prefix + "B"};
            if (has("A")) names.push_back(prefix + "A");
        } else if (has("Y")) {
            names = {prefix + "Y"};
        } else if (has("R")) {
            names = {prefix + "R"};
        } else if (layer.empty()) {
            return makeError(
                "cannot read image '{}': no R,G,B or Y channel (multi-layer EXRs need the "
                "beauty pass in the default layer)",
                path);
        } else {
            return makeError("cannot read image '{}': no layer '{}' (no {}R,G,B or {}Y channel)",
                             path, layer, prefix, prefix);
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
            frameBuffer.insert(
                names[c].c_str(),
                Imf::Slice::Make(Imf::FLOAT, image.pixels.data() + c, dw, xStride, yStride));
        }
        file.setFrameBuffer(frameBuffer);
        file.readPixels(dw.min.y, dw.max.y);
        return image;
    } catch (const std::exception& e) {
        return makeError("cannot read EXR image '{}': {}", path, oneLine(e.what()));
    }
}

// --- Radiance .hdr -------------------------------------------------------------------------

// Debian's stb_image loops forever on some truncated or corrupt Radiance files (end of file
// inside an RLE scanline reads as a zero-length run, again and again; so does a real zero-length
// run). So the file's structure is walked here first, every read bounded, exactly as stb will
// read it; stb only ever sees a file it decodes without reaching the end.
struct HdrLayout {
    int64_t width = 0;
    int64_t height = 0;
    size_t dataOffset = 0;
};

Result<HdrLayout> parseHdrHeader(std::span<const uint8_t> bytes, const std::string& path) {
    size_t at = 0;
    // One header line without its '\n'; nullopt at end of file (a header line ends in '\n') or
    // past stb's 1023-character line buffer.
    auto line = [&]() -> std::optional<std::string> {
        std::string out;
        while (at < bytes.size() && bytes[at] != '\n') {
            out += char(bytes[at++]);
            if (out.size() >= 1023) return std::nullopt;
        }
        if (at >= bytes.size()) return std::nullopt;
        ++at;
        return out;
    };
    std::optional<std::string> l = line();  // "#?RADIANCE", checked by sniff()
    bool rgbe = false;
    while (true) {
        l = line();
        if (!l)
            return makeError(
                "cannot read image '{}': the Radiance HDR header is truncated or corrupt", path);
        if (l->empty()) break;
        if (*l == "FORMAT=32-bit_rle_rgbe") rgbe = true;
    }
    if (!rgbe)
        return makeError(
            "cannot read image '{}': not an RGBE Radiance file (only "
            "FORMAT=32-bit_rle_rgbe is read)",
            path);
    l = line();
    int64_t h = 0;
    int64_t w = 0;
    char tail = 0;
    // The only orientation stb reads: "-Y height +X width".
    if (!l || l->find('\0') != std::string::npos ||
        std::sscanf(l->c_str(), "-Y %" SCNd64 " +X %" SCNd64 "%c", &h, &w, &tail) != 2)
        return makeError(
            "cannot read image '{}': unsupported Radiance HDR resolution line "
            "(only '-Y H +X W' is read)",
            path);
    return HdrLayout{w, h, at};
}

Status checkHdrScanlines(std::span<const uint8_t> bytes, const HdrLayout& layout,
                         const std::string& path) {
    const uint64_t w = uint64_t(layout.width);
    const uint64_t h = uint64_t(layout.height);
    const size_t size = bytes.size();
    size_t at = layout.dataOffset;
    auto truncated = [&](uint64_t row) {
        return makeError(
            "cannot read image '{}': the Radiance HDR file ends early, at scanline "
            "{} of {} (truncated: copy it again)",
            path, row, h);
    };
    auto corrupt = [&](uint64_t row) {
        return makeError(
            "cannot read image '{}': bad run length in Radiance HDR scanline {} "
            "(corrupt file)",
            path, row);
    };
    // Pixels stored flat (4 bytes each) from `from` to the end of the image.
    auto flat = [&](size_t from) -> Status {
        if (uint64_t(size - from) < w * h * 4) return truncated((size - from) / (w * 4));
        return {};
    };
    // stb's rule: widths outside [8, 32768) are stored flat; so is a file whose first scanline
    // does not start with the RLE marker (2, 2, length < 32768).
    if (w < 8 || w >= 32768) return flat(at);
    for (uint64_t row = 0; row < h; ++row) {
        if (size - at < 4) return truncated(row);
        const uint8_t* p = bytes.data() + at;
        if (p[0] != 2 || p[1] != 2 || (p[2] & 0x80)) {
            if (row == 0) return flat(at);
            return makeError(
                "cannot read image '{}': Radiance HDR scanline {} is not run-length "
                "encoded like those before it (corrupt file)",
                path, row);
        }
        const uint64_t length = uint64_t(p[2]) << 8 | p[3];
        if (length != w)
            return makeError(
                "cannot read image '{}': Radiance HDR scanline {} has length {}, not "
                "the width {} (corrupt file)",
                path, row, length, w);
        at += 4;
        for (int channel = 0; channel < 4; ++channel) {
            for (uint64_t x = 0; x < w;) {
                if (at >= size) return truncated(row);
                const uint8_t count = bytes[at++];
                if (count > 128) {  // a run: one value repeated count - 128 times
                    if (at >= size) return truncated(row);
                    ++at;
                    if (uint64_t(count - 128) > w - x) return corrupt(row);
                    x += count - 128;
                } else {  // count literal values
                    if (count == 0 || count > w - x) return corrupt(row);
                    if (size - at < count) return truncated(row);
                    at += count;
                    x += count;
                }
            }
        }
    }
    return {};
}

Result<ImageF> readHdr(std::span<const uint8_t> bytes, const std::string& path,
                       const ImageLimits& limits) {
    Result<HdrLayout> layout = parseHdrHeader(bytes, path);
    if (!layout) return layout.error();
    if (Status s = checkSize(path, "the Radiance HDR image", layout->width, layout->height, limits);
        !s)
        return s.error();
    if (Status s = checkHdrScanlines(bytes, *layout, path); !s) return s.error();
    if (bytes.size() > size_t(std::numeric_limits<int>::max()))
        return makeError("cannot read image '{}': the file is larger than 2 GiB", path);
    int w = 0;
    int h = 0;
    int n = 0;
    std::unique_ptr<float, decltype(&stbi_image_free)> data(
        stbi_loadf_from_memory(bytes.data(), int(bytes.size()), &w, &h, &n, 3), &stbi_image_free);
    if (!data)
        return makeError("cannot decode Radiance HDR image '{}': {}", path,
                         stbi_failure_reason() ? stbi_failure_reason() : "unknown error");
    if (w != layout->width || h != layout->height)
        return makeError("cannot decode Radiance HDR image '{}': inconsistent size", path);
    ImageF image;
    image.width = uint32_t(w);
    image.height = uint32_t(h);
    image.channels = 3;
    image.pixels.assign(data.get(), data.get() + size_t(w) * size_t(h) * 3);
    return image;
}

// --- PNG / JPEG ----------------------------------------------------------------------------

// Debian's stb_image (2022-09) does not check that a JPEG Huffman table holds at most 256 codes
// and writes past its table when one does (found by fuzz/fuzz_image). So every marker segment
// of the file is walked here first (ITU T.81 B.1.1.4, B.2.4.2), every length bounded, skipping
// entropy-coded data after each start of scan (progressive files define tables between scans),
// and a table with more than 256 codes is refused, as is a segment cut short. A file that ends
// inside a scan is left to stb, which reads the rest of the scan as zeros.
Status checkJpegTables(std::span<const uint8_t> bytes, const std::string& path) {
    auto corrupt = [&](const char* what) {
        return makeError("cannot decode image '{}': a JPEG image with {} (corrupt file)", path,
                         what);
    };
    const size_t size = bytes.size();
    size_t at = 2;  // after SOI
    while (true) {
        while (at + 1 < size && bytes[at] == 0xff && bytes[at + 1] == 0xff) ++at;  // fill bytes
        if (size - at < 4) return {};
        if (bytes[at] != 0xff) return corrupt("a malformed header");
        const uint8_t marker = bytes[at + 1];
        if (marker == 0xd9) return {};  // end of image
        const size_t length = size_t(bytes[at + 2]) << 8 | bytes[at + 3];
        if (length < 2) return corrupt("a malformed header segment");
        // stb reads a segment past the end of the file as zeros, tables included.
        if (length > size - at - 2) return corrupt("a header segment cut short (truncated file)");
        if (marker == 0xc4) {  // DHT: tables of (class/id, 16 counts, the codes)
            size_t t = at + 4;
            const size_t end = at + 2 + length;
            while (t < end) {
                if (end - t < 17) return corrupt("a cut-short Huffman table");
                size_t codes = 0;
                for (size_t i = 1; i <= 16; ++i) codes += bytes[t + i];
                if (codes > 256) return corrupt("a Huffman table of more than 256 codes");
                if (end - t - 17 < codes) return corrupt("a cut-short Huffman table");
                t += 17 + codes;
            }
        }
        at += 2 + length;
        if (marker == 0xda) {  // start of scan: entropy-coded data up to the next real marker
            while (at + 1 < size &&
                   !(bytes[at] == 0xff && bytes[at + 1] != 0 && bytes[at + 1] != 0xff &&
                     (bytes[at + 1] < 0xd0 || bytes[at + 1] > 0xd7)))
                ++at;
        }
    }
}

struct Decoded8 {
    std::unique_ptr<unsigned char, decltype(&stbi_image_free)> data{nullptr, &stbi_image_free};
    int width = 0;
    int height = 0;
    int channels = 0;  // in the file
};

// The header's size through stb's info reader (no pixel decoded yet), then the pixels.
Result<Decoded8> decode8(std::span<const uint8_t> bytes, const Sniffed& what,
                         const std::string& path, int wantChannels, const ImageLimits& limits) {
    if (bytes.size() > size_t(std::numeric_limits<int>::max()))
        return makeError("cannot read image '{}': the file is larger than 2 GiB", path);
    const int size = int(bytes.size());
    Decoded8 out;
    if (what.type == ContentType::Png) {
        // IHDR comes first (PNG spec 5.2): length, "IHDR", width, height, big-endian.
        auto be32 = [&](size_t at) {
            return uint32_t(bytes[at]) << 24 | uint32_t(bytes[at + 1]) << 16 |
                   uint32_t(bytes[at + 2]) << 8 | uint32_t(bytes[at + 3]);
        };
        if (bytes.size() < 33 || std::memcmp(bytes.data() + 12, "IHDR", 4) != 0)
            return makeError(
                "cannot decode image '{}': a PNG image without its IHDR header "
                "(truncated or corrupt)",
                path);
        if (Status s = checkSize(path, what.name, be32(16), be32(20), limits); !s) return s.error();
    }
    if (what.type == ContentType::Jpeg)
        if (Status s = checkJpegTables(bytes, path); !s) return s.error();
    if (!stbi_info_from_memory(bytes.data(), size, &out.width, &out.height, &out.channels))
        return makeError("cannot decode image '{}': {} with a corrupt header ({})", path, what.name,
                         stbi_failure_reason() ? stbi_failure_reason() : "unknown");
    if (Status s = checkSize(path, what.name, out.width, out.height, limits); !s) return s.error();
    int w = 0;
    int h = 0;
    out.data.reset(stbi_load_from_memory(bytes.data(), size, &w, &h, &out.channels, wantChannels));
    if (!out.data)
        return makeError("cannot decode image '{}': {} that is corrupt or truncated ({})", path,
                         what.name, stbi_failure_reason() ? stbi_failure_reason() : "unknown");
    if (w != out.width || h != out.height)
        return makeError("cannot decode image '{}': inconsistent size", path);
    return out;
}

Result<ImageF> readLdr(std::span<const uint8_t> bytes, const Sniffed& what, const std::string& path,
                       const ImageLimits& limits) {
    Result<Decoded8> decoded = decode8(bytes, what, path, 0, limits);
    if (!decoded) return decoded.error();
    const int n = decoded->channels;
    const size_t pixels = size_t(decoded->width) * size_t(decoded->height);
    // Grey+alpha becomes RGBA so callers see 1, 3 or 4 channels only.
    const int outChannels = n == 2 ? 4 : n;
    ImageF image;
    image.width = uint32_t(decoded->width);
    image.height = uint32_t(decoded->height);
    image.channels = uint32_t(outChannels);
    image.ldrSrgb = true;
    image.pixels.resize(pixels * size_t(outChannels));
    for (size_t p = 0; p < pixels; ++p) {
        const unsigned char* src = decoded->data.get() + p * size_t(n);
        float* dst = image.pixels.data() + p * size_t(outChannels);
        if (n == 2) {
            dst[0] = dst[1] = dst[2] = src[0] / 255.0f;
            dst[3] = src[1] / 255.0f;
        } else {
            for (int c = 0; c < n; ++c) dst[c] = src[c] / 255.0f;
        }
    }
    return image;
}

}  // namespace

Result<ImageF> readImage(const std::string& path, const ImageLimits& limits) {
    if (Status s = checkReadable(path); !s) return s.error();
    const std::string ext = lowerExtension(path);
    ContentType expected = ContentType::Other;
    if (ext == ".exr")
        expected = ContentType::Exr;
    else if (ext == ".hdr")
        expected = ContentType::Hdr;
    else if (ext == ".png")
        expected = ContentType::Png;
    else if (ext == ".jpg" || ext == ".jpeg")
        expected = ContentType::Jpeg;
    else
        return makeError(
            "cannot read image '{}': unsupported extension '{}' (use .exr, .hdr, .png, .jpg)", path,
            ext);
    Result<std::vector<uint8_t>> bytes = readFileBytes(path, limits);
    if (!bytes) return bytes.error();
    const Sniffed what = sniff(*bytes);
    if (what.type != expected) {
        // Indexed by ContentType.
        static const char* const kFormat[] = {"OpenEXR", "Radiance HDR", "PNG", "JPEG"};
        static const char* const kExtension[] = {".exr", ".hdr", ".png", ".jpg"};
        return makeError("cannot read image '{}': the name says {} but the file is {}{}", path,
                         kFormat[int(expected)], what.name,
                         what.type == ContentType::Other
                             ? std::string(" (damaged, or not an image)")
                             : fmt::format(" (rename it to {})", kExtension[int(what.type)]));
    }
    switch (what.type) {
        case ContentType::Exr:
            return readExr(*bytes, path, limits);
        case ContentType::Hdr:
            return readHdr(*bytes, path, limits);
        default:
            return readLdr(*bytes, what, path, limits);
    }
}

Result<ImageF> readExrLayer(const std::string& path, const std::string& layer,
                            const ImageLimits& limits) {
    Result<std::vector<uint8_t>> bytes = readFileBytes(path, limits);
    if (!bytes) return bytes.error();
    if (sniff(*bytes).type != ContentType::Exr)
        return makeError("cannot read image '{}': not an OpenEXR file", path);
    return readExr(*bytes, path, limits, layer);
}

Result<ImageSize> encodedImageSize(std::span<const uint8_t> bytes, const std::string& name) {
    const Sniffed what = sniff(bytes);
    auto size = [&](int64_t w, int64_t h) -> Result<ImageSize> {
        if (w <= 0 || h <= 0 || w > INT32_MAX || h > INT32_MAX)
            return makeError("cannot read image '{}': its header says {}x{} pixels (corrupt file)",
                             name, w, h);
        return ImageSize{uint32_t(w), uint32_t(h)};
    };
    switch (what.type) {
        case ContentType::Exr: {
            Result<std::array<int32_t, 4>> window = exrDataWindow(bytes, name);
            if (!window) return window.error();
            const auto& b = *window;
            return size(int64_t(b[2]) - b[0] + 1, int64_t(b[3]) - b[1] + 1);
        }
        case ContentType::Hdr: {
            Result<HdrLayout> layout = parseHdrHeader(bytes, name);
            if (!layout) return layout.error();
            return size(layout->width, layout->height);
        }
        case ContentType::Png:
        case ContentType::Jpeg: {
            if (what.type == ContentType::Jpeg)
                if (Status s = checkJpegTables(bytes, name); !s) return s.error();
            int w = 0, h = 0, channels = 0;
            if (bytes.size() > size_t(INT32_MAX) ||
                !stbi_info_from_memory(bytes.data(), int(bytes.size()), &w, &h, &channels))
                return makeError("cannot decode image '{}': {} with a corrupt header", name,
                                 what.name);
            return size(w, h);
        }
        case ContentType::Other:
            break;
    }
    return makeError("cannot read image '{}': it is {}", name, what.name);
}

Result<ImageSize> imageFileSize(const std::string& path, const ImageLimits& limits) {
    Result<std::vector<uint8_t>> bytes = readFileBytes(path, limits);
    if (!bytes) return bytes.error();
    return encodedImageSize(*bytes, path);
}

Result<ImageRgba8> decodePngOrJpeg(std::span<const uint8_t> bytes, const std::string& name,
                                   const ImageLimits& limits) {
    const Sniffed what = sniff(bytes);
    if (what.type != ContentType::Png && what.type != ContentType::Jpeg)
        return makeError("cannot decode image '{}': it is {}, not PNG or JPEG", name, what.name);
    Result<Decoded8> decoded = decode8(bytes, what, name, 4, limits);
    if (!decoded) return decoded.error();
    ImageRgba8 image;
    image.width = uint32_t(decoded->width);
    image.height = uint32_t(decoded->height);
    image.pixels.assign(decoded->data.get(),
                        decoded->data.get() + size_t(image.width) * image.height * 4);
    return image;
}

Status writeExr(const std::string& path, const ImageF& image) {
    if (image.channels != 1 && image.channels != 3 && image.channels != 4)
        return makeError("cannot write EXR image '{}': {} channels (use 1, 3 or 4)", path,
                         image.channels);
    return writeExrLayers(path, {ExrLayer{"", &image}});
}

namespace {

std::vector<std::string> exrChannelNames(const ExrLayer& layer) {
    std::vector<std::string> names;
    switch (layer.image->channels) {
        case 1:
            names = {"Y"};
            break;
        case 3:
            names = {"R", "G", "B"};
            break;
        case 4:
            names = {"R", "G", "B", "A"};
            break;
    }
    if (!layer.name.empty())
        for (std::string& n : names) n = layer.name + "." + n;
    return names;
}

// The checks writeExrLayers makes before writing anything (`name`: the file, for messages).
Status checkExrLayers(const std::string& name, const std::vector<ExrLayer>& layers) {
    if (layers.empty()) return makeError("cannot write EXR image '{}': no layers", name);
    const uint32_t width = layers.front().image->width, height = layers.front().image->height;
    for (const ExrLayer& layer : layers) {
        const ImageF& image = *layer.image;
        if (image.width == 0 || image.height == 0 || image.width != width ||
            image.height != height ||
            image.pixels.size() != size_t(image.width) * image.height * image.channels ||
            exrChannelNames(layer).empty())
            return makeError(
                "cannot write EXR image '{}': layer '{}' is empty, of another size or has {} "
                "channels (use 1, 3 or 4)",
                name, layer.name, image.channels);
    }
    return {};
}

// "HH:MM:SS:FF" (';' before FF: drop frame) as OpenEXR's TimeCode, which checks the ranges.
Result<Imf::TimeCode> exrTimeCode(const std::string& name, const std::string& text) {
    auto field = [&](size_t at) { return (text[at] - '0') * 10 + (text[at + 1] - '0'); };
    bool digits =
        text.size() == 11 && text[2] == ':' && text[5] == ':' && (text[8] == ':' || text[8] == ';');
    for (const size_t at : {size_t(0), size_t(3), size_t(6), size_t(9)})
        digits = digits && std::isdigit(uint8_t(text[at])) && std::isdigit(uint8_t(text[at + 1]));
    try {
        if (digits) return Imf::TimeCode(field(0), field(3), field(6), field(9), text[8] == ';');
    } catch (const std::exception&) {  // a field out of its range: the message below
    }
    return makeError("cannot write EXR image '{}': timecode '{}' is not HH:MM:SS:FF", name, text);
}

Imath::M44f exrMatrix(const std::array<float, 16>& m) {
    return Imath::M44f(m[0], m[1], m[2], m[3], m[4], m[5], m[6], m[7], m[8], m[9], m[10], m[11],
                       m[12], m[13], m[14], m[15]);
}

// The standard attributes that are set (the timecode already read).
void addExrAttributes(Imf::Header& header, const ExrFrameAttributes& a,
                      const std::optional<Imf::TimeCode>& timeCode) {
    if (timeCode) Imf::addTimeCode(header, *timeCode);
    if (a.fpsNum > 0 && a.fpsDen > 0)
        Imf::addFramesPerSecond(header, Imf::Rational(a.fpsNum, unsigned(a.fpsDen)));
    if (a.worldToCamera) Imf::addWorldToCamera(header, exrMatrix(*a.worldToCamera));
    if (a.worldToNDC) Imf::addWorldToNDC(header, exrMatrix(*a.worldToNDC));
    if (!a.capDate.empty()) Imf::addCapDate(header, a.capDate);
    if (a.utcOffset) Imf::addUtcOffset(header, *a.utcOffset);
    for (const auto& [key, value] : a.strings) header.insert(key, Imf::StringAttribute(value));
}

// Writes checked layers to an OpenEXR output (a file name or a stream).
template <typename Target>
void writeExrTo(Target&& target, const std::vector<ExrLayer>& layers,
                const ExrFrameAttributes& attributes = {},
                const std::optional<Imf::TimeCode>& timeCode = {}) {
    const uint32_t width = layers.front().image->width, height = layers.front().image->height;
    Imf::Header header{int(width), int(height)};
    header.compression() = Imf::ZIP_COMPRESSION;
    addExrAttributes(header, attributes, timeCode);
    Imf::FrameBuffer frameBuffer;
    for (const ExrLayer& layer : layers) {
        const ImageF& image = *layer.image;
        const std::vector<std::string> names = exrChannelNames(layer);
        const size_t xStride = sizeof(float) * image.channels;
        const size_t yStride = xStride * image.width;
        for (size_t c = 0; c < names.size(); ++c) {
            header.channels().insert(names[c], Imf::Channel(Imf::FLOAT));
            // OpenEXR only reads through this pointer; its API is not const-correct.
            char* base = reinterpret_cast<char*>(const_cast<float*>(image.pixels.data() + c));
            frameBuffer.insert(names[c], Imf::Slice(Imf::FLOAT, base, xStride, yStride));
        }
    }
    Imf::OutputFile file(std::forward<Target>(target), header);
    file.setFrameBuffer(frameBuffer);
    file.writePixels(int(height));
}

// An OpenEXR output stream on a descriptor the caller owns (an AtomicFile's temporary): the
// writer seeks back to fill in the line offsets, so the file must be seekable. The first error
// is kept, since OpenEXR swallows what its destructor's last write throws.
class FdOStream : public Imf::OStream {
public:
    FdOStream(int fd, const std::string& name) : Imf::OStream(name.c_str()), fd_(fd) {}

    void write(const char c[], int n) override {
        for (size_t done = 0; done < size_t(n);) {
            const ssize_t w = ::write(fd_, c + done, size_t(n) - done);
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0) fail(w < 0 ? errno : ENOSPC);
            done += size_t(w);
        }
    }
    uint64_t tellp() override {
        const off_t at = ::lseek(fd_, 0, SEEK_CUR);
        if (at < 0) fail(errno);
        return uint64_t(at);
    }
    void seekp(uint64_t pos) override {
        if (::lseek(fd_, off_t(pos), SEEK_SET) < 0) fail(errno);
    }
    int error() const { return error_; }

private:
    [[noreturn]] void fail(int err) {
        if (error_ == 0) error_ = err;
        throw std::runtime_error(std::strerror(err));
    }
    int fd_;
    int error_ = 0;
};

}  // namespace

Status writeExrLayers(const std::string& path, const std::vector<ExrLayer>& layers) {
    if (lowerExtension(path) != ".exr")
        return makeError("cannot write EXR image '{}': the file name must end in .exr", path);
    if (Status s = checkExrLayers(path, layers); !s) return s;
    if (Status s = checkWritableFolder(path); !s) return s;
    try {
        writeExrTo(path.c_str(), layers);
    } catch (const std::exception& e) {
        return makeError("cannot write EXR image '{}': {} (check the folder is writable)", path,
                         e.what());
    }
    return {};
}

Status writeExrLayers(int fd, const std::string& name, const std::vector<ExrLayer>& layers,
                      const ExrFrameAttributes& attributes) {
    if (Status s = checkExrLayers(name, layers); !s) return s;
    std::optional<Imf::TimeCode> timeCode;
    if (!attributes.timeCode.empty()) {
        Result<Imf::TimeCode> read = exrTimeCode(name, attributes.timeCode);
        if (!read) return read.error();
        timeCode = *read;
    }
    FdOStream stream(fd, name);
    try {
        writeExrTo(stream, layers, attributes, timeCode);
    } catch (const std::exception& e) {
        return makeError("cannot write EXR image '{}': {} (is the disk full?)", name, e.what());
    }
    if (stream.error() != 0)
        return makeError("cannot write EXR image '{}': {} (is the disk full?)", name,
                         std::strerror(stream.error()));
    return {};
}

Status writeExr(int fd, const std::string& name, const ImageF& image) {
    if (image.channels != 1 && image.channels != 3 && image.channels != 4)
        return makeError("cannot write EXR image '{}': {} channels (use 1, 3 or 4)", name,
                         image.channels);
    return writeExrLayers(fd, name, {ExrLayer{"", &image}});
}

bool isCompleteExr(const std::string& path) {
    try {
        Imf::InputFile file(path.c_str());
        if (!file.isComplete()) return false;
        // The offset table can be whole while the data it points at is not (a file cut short):
        // every scanline must decode.
        const Imath::Box2i window = file.header().dataWindow();
        const size_t width = size_t(window.max.x - window.min.x + 1);
        std::vector<float> row(width);
        Imf::FrameBuffer frameBuffer;
        for (auto c = file.header().channels().begin(); c != file.header().channels().end(); ++c)
            frameBuffer.insert(
                c.name(), Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(row.data() - window.min.x),
                                     sizeof(float), 0));
        file.setFrameBuffer(frameBuffer);
        file.readPixels(window.min.y, window.max.y);
        return true;
    } catch (const std::exception&) {
        return false;
    }
}

namespace {
// libpng's simplified writer for an 8-bit RGB image: writePng and encodePng use the same one, so
// a frame written to a file and one encoded to memory are the same bytes.
png_image rgbPngImage(uint32_t width, uint32_t height) {
    png_image png;
    std::memset(&png, 0, sizeof(png));
    png.version = PNG_IMAGE_VERSION;
    png.width = width;
    png.height = height;
    png.format = PNG_FORMAT_RGB;
    return png;
}
}  // namespace

Status writePng(const std::string& path, uint32_t width, uint32_t height,
                const std::vector<uint8_t>& rgb8) {
    if (lowerExtension(path) != ".png")
        return makeError("cannot write PNG image '{}': the file name must end in .png", path);
    if (width == 0 || height == 0 || rgb8.size() != size_t(width) * height * 3)
        return makeError("cannot write PNG image '{}': {} bytes for {}x{} RGB (need {})", path,
                         rgb8.size(), width, height, size_t(width) * height * 3);
    if (Status s = checkWritableFolder(path); !s) return s;

    png_image png = rgbPngImage(width, height);
    errno = 0;
    if (!png_image_write_to_file(&png, path.c_str(), 0, rgb8.data(), 0, nullptr)) {
        const std::string reason = errno ? std::strerror(errno) : png.message;
        png_image_free(&png);
        return makeError("cannot write PNG image '{}': {} (check the folder is writable)", path,
                         reason);
    }
    return {};
}

Result<std::vector<uint8_t>> encodePng(uint32_t width, uint32_t height,
                                       const std::vector<uint8_t>& rgb8, const std::string& name) {
    if (width == 0 || height == 0 || rgb8.size() != size_t(width) * height * 3)
        return makeError("cannot encode PNG image '{}': {} bytes for {}x{} RGB (need {})", name,
                         rgb8.size(), width, height, size_t(width) * height * 3);
    png_image png = rgbPngImage(width, height);
    // The same encoder and settings as writePng (png_image_write_to_file), so the same bytes:
    // asked for the size first, then written.
    png_alloc_size_t size = 0;
    if (!png_image_write_to_memory(&png, nullptr, &size, 0, rgb8.data(), 0, nullptr)) {
        const std::string reason = png.message;
        png_image_free(&png);
        return makeError("cannot encode PNG image '{}': {}", name, reason);
    }
    std::vector<uint8_t> bytes(size);
    if (!png_image_write_to_memory(&png, bytes.data(), &size, 0, rgb8.data(), 0, nullptr)) {
        const std::string reason = png.message;
        png_image_free(&png);
        return makeError("cannot encode PNG image '{}': {}", name, reason);
    }
    bytes.resize(size);
    return bytes;
}

}  // namespace previs
