#pragma once

// Camera and display colour through OpenColorIO (issue 54): a camera that sends Rec.709 or a log
// encoding (ARRI LogC3, Sony S-Log3, Panasonic V-Log, Canon Log 2/3, RED Log3G10) is decoded to
// the renderer's scene-linear working space (linear Rec.709 primaries, colour/
// ocio_builtin_config.h), and the working space is shown through a display's view. Either from
// OCIO 2.1's built-in transforms (colour/ocio_builtin_config.h) or from a config file the user
// names, connected through its aces_interchange role. Built only when configured: a camera
// with the hand-written curves (vision/inverse_tone_map.h) never touches OCIO.

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "base/result.h"

namespace previs {

// Where a colour transform comes from: a config file ("" = the built-in one) and, for error
// messages, the config key that named it ("cameras.scene.colour").
struct OcioSource {
    OcioSource(std::string configPath_, std::string key_)
        : configPath(std::move(configPath_)), key(std::move(key_)) {}
    // For a command line: messages name its options ("--colour", "--ocio-config") in place of
    // '<key>.input' and '<key>.ocio_config'.
    static OcioSource fromOptions(std::string configPath, std::string inputOption,
                                  std::string configOption) {
        OcioSource s(std::move(configPath), "");
        s.inputOption = std::move(inputOption);
        s.configOption = std::move(configOption);
        return s;
    }

    std::string configPath;
    std::string key;
    std::string inputOption;
    std::string configOption;
};

// How a camera's 8-bit codes span the signal. Full: 0–255 (what previs assumed before `range`).
// Legal (video, "limited"): Rec.709 over SDI/HDMI puts black at 16 and white at 235, so a code v
// is the signal (v − 16)/219, applied to each of R, G, B before the input transform; codes below
// 16 and above 235 (super-whites) map below 0 and above 1, kept, not clipped. A 10-bit legal
// signal (64–940) is exactly the 8-bit one times 4, so once captured to 8 bits it maps the same.
enum class CodeRange { Full, Legal };

// A camera's encoding → the working space. Immutable and thread-safe once built (OCIO's CPU
// processors are), so one is shared by every thread that linearises the camera's frames.
class CameraColourTransform {
public:
    // `input`: a colour space (or alias or role) of the config. An unknown name, an unreadable
    // config or one without an aces_interchange role is one message naming the key and the file,
    // with a few valid names. `range`: how the codes span the signal, undone first.
    static Result<std::shared_ptr<const CameraColourTransform>> create(
        const OcioSource& source, const std::string& input, CodeRange range = CodeRange::Full);
    ~CameraColourTransform();

    // 8-bit RGB (rows of `width` packed triples, `srcStrideBytes` apart) → float RGB in the
    // working space, `dstStrideBytes` apart. Through OCIO's processor optimised for 8-bit input:
    // the curve becomes a 256-entry table, then the gamut matrix.
    void apply8(const uint8_t* src, std::ptrdiff_t srcStrideBytes, float* dst,
                std::ptrdiff_t dstStrideBytes, int width, int height) const;
    // Float RGB code values in [0, 1] (an 8-bit image read as floats) → working space, in place.
    void applyFloat(float* rgb, int width, int height, std::ptrdiff_t strideBytes) const;

    // "ARRI LogC3 (EI800) (built-in)", "LogC3 from /etc/previs/studio.ocio": for the log.
    const std::string& description() const { return description_; }

    struct Processors;

private:
    CameraColourTransform(std::unique_ptr<const Processors> processors, std::string description);
    std::unique_ptr<const Processors> processors_;
    std::string description_;
};

// The working space → a display's view, encoded in 8 bits for that display.
class DisplayColourTransform {
public:
    // `display`/`view`: "" = the config's default display and that display's default view (the
    // built-in config's: "sRGB", "ACES 1.0 - SDR Video").
    static Result<std::shared_ptr<const DisplayColourTransform>> create(const OcioSource& source,
                                                                        const std::string& display,
                                                                        const std::string& view);
    ~DisplayColourTransform();

    // Float RGB in the working space (3 floats a pixel, rows packed) → 8-bit RGB, rows packed.
    void apply(const float* rgb, int width, int height, uint8_t* out) const;
    // A renderer's image (`channels` ≥ 3 floats a pixel: RGB first, alpha ignored), each channel
    // times `gain` first (the camera's exposure and white balance undone), → 8-bit RGB. Packs
    // the image to RGB in place: `pixels` is scratch afterwards (a frame is not copied).
    void applyScaled(float* pixels, int channels, int width, int height,
                     const std::array<float, 3>& gain, uint8_t* out) const;

    const std::string& description() const { return description_; }

    // The view as apply() runs it, for a device to run the same (render/display_pass.h): a
    // working-space value v goes to ACEScct per channel (v ≤ 2⁻⁷: 10.5402377416545·v +
    // 0.0729055341958355, else (log2 v + 9.72)/17.52), clamped to [0, 1], then through this
    // kLutSize³ table by tetrahedral interpolation to display code values in [0, 1]. RGB per
    // node, red fastest, then green, then blue. The grid is 0.27 stop a step up to 222, so
    // shadows and highlights are as fine as mid-tones.
    static constexpr uint32_t kLutSize = 65;
    const std::shared_ptr<const std::vector<float>>& lut() const { return lut_; }

    struct Processors;

private:
    DisplayColourTransform(std::unique_ptr<const Processors> processors,
                           std::shared_ptr<const std::vector<float>> lut, std::string description);
    std::unique_ptr<const Processors> processors_;
    std::shared_ptr<const std::vector<float>> lut_;
    std::string description_;
};

}  // namespace previs

namespace previs {

// What a take must hold for an OCIO config to work elsewhere (take/take_files.h): the files its
// FileTransforms name (a .cube, .spi1d, .csp … in any colour space, look, view transform or
// named transform), found through its search_path and context as OCIO finds them, absolute and
// normalised, each once, the config itself not included. A file OCIO cannot find is left out
// (a colour space naming it fails when used, as it does without a take).
Result<std::vector<std::string>> ocioConfigFiles(const std::string& configPath);

// The text of a copy of the config that keeps working once the config and its files are copied
// keeping their layout relative to each other: the file's own bytes, or, when its search_path
// names absolute folders, OCIO's serialisation of it with each absolute folder made relative to
// the config's own folder.
Result<std::string> relocatableOcioConfig(const std::string& configPath);

}  // namespace previs
