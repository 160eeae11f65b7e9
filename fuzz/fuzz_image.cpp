// readImage on EXR, Radiance HDR, PNG and JPEG input. The extension is chosen from the input's
// magic bytes (so each decoder is reached) or, for anything else, from its size, so the
// content-type check is fuzzed too.
#include "fuzz/fuzz_support.h"
#include "image/image.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace previs;
    const std::string_view text = fuzz::asText(data, size);
    const char* ext = nullptr;
    if (text.starts_with("\x76\x2f\x31\x01"))
        ext = ".exr";
    else if (text.starts_with("#?"))
        ext = ".hdr";
    else if (text.starts_with("\x89PNG"))
        ext = ".png";
    else if (text.starts_with("\xff\xd8"))
        ext = ".jpg";
    else
        ext = (const char*[]){".exr", ".hdr", ".png", ".jpg"}[size % 4];
    const std::string path = fuzz::writeScratch(std::string("image") + ext, text);
    // A small limit keeps each run fast; the limit itself is what the header check enforces.
    ImageLimits limits;
    limits.maxWidth = 2048;
    limits.maxHeight = 2048;
    Result<ImageF> image = readImage(path, limits);
    if (image.ok() &&
        image->pixels.size() != size_t(image->width) * image->height * image->channels)
        __builtin_trap();
    Result<ImageRgba8> texture =
        decodePngOrJpeg(std::span<const uint8_t>(data, size), "fuzz", limits);
    if (texture.ok() && texture->pixels.size() != size_t(texture->width) * texture->height * 4)
        __builtin_trap();
    return 0;
}
