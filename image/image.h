#pragma once

// Image files in and out: OpenEXR (linear float), Radiance .hdr, PNG/JPEG (8-bit, sRGB-encoded).
// Every error names the file, what is wrong and what to do.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "base/result.h"

namespace previs {

// Interleaved float pixels, row-major, row 0 at the top.
struct ImageF {
    uint32_t width = 0;
    uint32_t height = 0;
    uint32_t channels = 0;  // 1 (grey / "Y"), 3 (RGB) or 4 (RGBA)
    std::vector<float> pixels;
    // True for PNG/JPEG: the values are the 8-bit codes / 255, still sRGB-encoded (the caller
    // decides how to linearise or inverse tone map them). False: linear HDR (EXR, .hdr).
    bool ldrSrgb = false;

    float at(uint32_t x, uint32_t y, uint32_t c) const {
        return pixels[(size_t(y) * width + x) * channels + c];
    }
};

// The largest image a reader decodes, per axis. Checked against the header before any pixel is
// decoded, so a hostile or mistaken file (a 100000 x 100000 PNG is a few kilobytes) cannot
// exhaust memory (DESIGN.md §7). 16384 x 16384 RGBA float is 4 GiB, the most the box can hold.
struct ImageLimits {
    uint32_t maxWidth = 16384;
    uint32_t maxHeight = 16384;
    // The file itself, checked before it is read (a FIFO or a device is refused): 2 GiB holds an
    // uncompressed 16384 x 8192 RGBA float map.
    uint64_t maxFileBytes = uint64_t(2) << 30;
};

// Reads .exr (float; channels R,G,B[,A] or Y), .hdr (Radiance RGBE), .png/.jpg/.jpeg. The
// content must be what the extension says (a PNG named .exr is refused, naming what it is),
// the header's size must be within `limits`, and a truncated or corrupt file is an error,
// never a hang or a crash.
Result<ImageF> readImage(const std::string& path, const ImageLimits& limits = {});

// One layer of a multi-layer OpenEXR (writeExrLayers' "<layer>.R", ... channels; "" the default
// layer), with readImage's checks.
Result<ImageF> readExrLayer(const std::string& path, const std::string& layer,
                            const ImageLimits& limits = {});

struct ImageSize {
    uint32_t width = 0;
    uint32_t height = 0;
};

// The size an image's header declares (OpenEXR's data window, Radiance, PNG, JPEG), no pixel
// decoded: a caller that knows what size to expect refuses a 38 KB JPEG that declares 30000 x
// 30000 before decoding costs gigabytes. `name` names the image in errors.
Result<ImageSize> encodedImageSize(std::span<const uint8_t> bytes, const std::string& name);

// The same for a file (read as readImage reads it).
Result<ImageSize> imageFileSize(const std::string& path, const ImageLimits& limits = {});

// An 8-bit RGBA image, row 0 at the top (a decoded glTF texture).
struct ImageRgba8 {
    uint32_t width = 0;
    uint32_t height = 0;
    std::vector<uint8_t> pixels;  // width * height * 4
};

// Decodes a PNG or JPEG held in memory (glTF allows only these two for textures), with the
// same checks as readImage; `name` names the image in errors.
Result<ImageRgba8> decodePngOrJpeg(std::span<const uint8_t> bytes, const std::string& name,
                                   const ImageLimits& limits = {});

// Writes float32 (never half: linear HDR must survive a round trip bit-exactly), lossless ZIP
// compression. 1 channel is written as "Y", 3 as RGB, 4 as RGBA.
Status writeExr(const std::string& path, const ImageF& image);

// A layer of a multi-layer EXR: its channels are "<name>.R", ".G", ".B" (".A", or ".Y" for one
// channel), the layer convention Nuke and Blender's compositor read; an empty name writes plain
// R, G, B (the default layer a viewer shows).
struct ExrLayer {
    std::string name;
    const ImageF* image = nullptr;
};

// OpenEXR's standard attributes (ImfStandardAttributes.h) that a frame carries for post, each
// written only when set. Matrices are as Imath stores them: row-major, for row vectors
// (p' = p · M, the translation in the last row).
struct ExrFrameAttributes {
    std::string timeCode;        // SMPTE "HH:MM:SS:FF" (';' before FF: drop frame)
    int fpsNum = 0, fpsDen = 0;  // framesPerSecond; 0 = none
    std::optional<std::array<float, 16>> worldToCamera, worldToNDC;
    std::string capDate;             // "YYYY:MM:DD hh:mm:ss", local time
    std::optional<float> utcOffset;  // seconds: UTC = local time + utcOffset
    std::vector<std::pair<std::string, std::string>> strings;  // other string attributes
};

// Writes layers of one size into one EXR, float32 and ZIP as writeExr.
Status writeExrLayers(const std::string& path, const std::vector<ExrLayer>& layers);

// writeExr and writeExrLayers to an open, seekable descriptor the caller owns (an AtomicFile's
// temporary, base/atomic_file.h), the same bytes as to a file; `name` names it in errors.
// A timeCode that does not read as one is an error, before anything is written.
Status writeExr(int fd, const std::string& name, const ImageF& image);
Status writeExrLayers(int fd, const std::string& name, const std::vector<ExrLayer>& layers,
                      const ExrFrameAttributes& attributes = {});

// Whether `path` is an EXR whose header reads and whose every scanline is present.
bool isCompleteExr(const std::string& path);

// Writes an 8-bit RGB PNG; rgb8 holds width*height*3 bytes, row 0 at the top.
Status writePng(const std::string& path, uint32_t width, uint32_t height,
                const std::vector<uint8_t>& rgb8);

// The bytes writePng writes, in memory (for an AtomicFile); `name` names the image in errors.
Result<std::vector<uint8_t>> encodePng(uint32_t width, uint32_t height,
                                       const std::vector<uint8_t>& rgb8, const std::string& name);

}  // namespace previs
