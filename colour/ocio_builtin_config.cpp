#include "colour/ocio_builtin_config.h"

#include <array>

namespace previs {
namespace {

namespace OCIO = OCIO_NAMESPACE;

// A camera encoding by its name in ACES's OCIO configs and OCIO's built-in transform to
// ACES2065-1 (OCIO 2.1, BuiltinTransformRegistry).
struct BuiltinCamera {
    const char* name;
    const char* style;
};
constexpr std::array<BuiltinCamera, 11> kCameras{{
    {"ARRI LogC3 (EI800)", "ARRI_ALEXA-LOGC-EI800-AWG_to_ACES2065-1"},
    {"Sony S-Log3 S-Gamut3", "SONY_SLOG3-SGAMUT3_to_ACES2065-1"},
    {"Sony S-Log3 S-Gamut3.Cine", "SONY_SLOG3-SGAMUT3.CINE_to_ACES2065-1"},
    {"Sony S-Log3 Venice S-Gamut3", "SONY_SLOG3-SGAMUT3-VENICE_to_ACES2065-1"},
    {"Sony S-Log3 Venice S-Gamut3.Cine", "SONY_SLOG3-SGAMUT3.CINE-VENICE_to_ACES2065-1"},
    {"Panasonic V-Log V-Gamut", "PANASONIC_VLOG-VGAMUT_to_ACES2065-1"},
    {"Canon Log 2 Cinema Gamut", "CANON_CLOG2-CGAMUT_to_ACES2065-1"},
    {"Canon Log 3 Cinema Gamut", "CANON_CLOG3-CGAMUT_to_ACES2065-1"},
    {"RED Log3G10 REDWideGamutRGB", "RED_LOG3G10-RWG_to_ACES2065-1"},
    {"RED REDLogFilm REDWideGamutRGB", "RED_REDLOGFILM-RWG_to_ACES2065-1"},
    {"ACEScct", "ACEScct_to_ACES2065-1"},
}};

OCIO::TransformRcPtr builtin(const char* style,
                             OCIO::TransformDirection direction = OCIO::TRANSFORM_DIR_FORWARD) {
    OCIO::BuiltinTransformRcPtr t = OCIO::BuiltinTransform::Create();
    t->setStyle(style);
    t->setDirection(direction);
    return t;
}

OCIO::TransformRcPtr group(std::initializer_list<OCIO::TransformRcPtr> steps) {
    OCIO::GroupTransformRcPtr g = OCIO::GroupTransform::Create();
    for (const OCIO::TransformRcPtr& t : steps) g->appendTransform(t);
    return g;
}

// Linear Rec.709 → ACES2065-1 through ACEScg (AP1): OCIO 2.1 has a built-in AP1 ↔ Rec.709
// matrix (Bradford) but none from AP0 to Rec.709.
OCIO::TransformRcPtr acesFromLinearRec709() {
    return group({builtin("UTILITY - ACES-AP1_to_LINEAR-REC709_BFD", OCIO::TRANSFORM_DIR_INVERSE),
                  builtin("ACEScg_to_ACES2065-1")});
}

// A video curve with a linear toe (ITU-R BT.709's camera OETF, IEC 61966-2-1's sRGB), decoded:
// ExponentWithLinearTransform's forward direction is encoded → linear.
OCIO::TransformRcPtr decodeCurve(double gamma, double offset) {
    OCIO::ExponentWithLinearTransformRcPtr t = OCIO::ExponentWithLinearTransform::Create();
    t->setGamma({gamma, gamma, gamma, 1.0});
    t->setOffset({offset, offset, offset, 0.0});
    return t;
}

void addSpace(const OCIO::ConfigRcPtr& config, const char* name,
              std::initializer_list<const char*> aliases, const OCIO::ConstTransformRcPtr& toAces,
              const char* family) {
    OCIO::ColorSpaceRcPtr cs = OCIO::ColorSpace::Create(OCIO::REFERENCE_SPACE_SCENE);
    cs->setName(name);
    cs->setFamily(family);
    for (const char* alias : aliases) cs->addAlias(alias);
    if (toAces) cs->setTransform(toAces, OCIO::COLORSPACE_DIR_TO_REFERENCE);
    config->addColorSpace(cs);
}

// A display's encoding of a view, as an output colour space (from the scene reference).
void addView(const OCIO::ConfigRcPtr& config, const char* display, const char* displayStyle,
             const char* view, const char* viewStyle) {
    const std::string name = std::string(display) + " - " + view;
    OCIO::ColorSpaceRcPtr cs = OCIO::ColorSpace::Create(OCIO::REFERENCE_SPACE_SCENE);
    cs->setName(name.c_str());
    cs->setFamily("Display");
    cs->setTransform(group({builtin(viewStyle), builtin(displayStyle)}),
                     OCIO::COLORSPACE_DIR_FROM_REFERENCE);
    config->addColorSpace(cs);
    config->addDisplayView(display, view, name.c_str(), "");
}

void addDisplays(const OCIO::ConfigRcPtr& config) {
    const char* sdrVideo = "ACES-OUTPUT - ACES2065-1_to_CIE-XYZ-D65 - SDR-VIDEO_1.0";
    const char* plain = "UTILITY - ACES-AP0_to_CIE-XYZ-D65_BFD";
    for (auto [display, style] :
         {std::pair{"sRGB", "DISPLAY - CIE-XYZ-D65_to_sRGB"},
          std::pair{"Rec.1886 Rec.709", "DISPLAY - CIE-XYZ-D65_to_REC.1886-REC.709"}}) {
        // The first view is the display's default.
        addView(config, display, style, "ACES 1.0 - SDR Video", sdrVideo);
        addView(config, display, style, "Un-tone-mapped", plain);
    }
    config->setActiveDisplays("sRGB, Rec.1886 Rec.709");
}

OCIO::ConstConfigRcPtr makeBuiltinConfig() {
    OCIO::ConfigRcPtr config = OCIO::Config::Create();
    addSpace(config, kInterchangeColourSpace, {"aces"}, nullptr, "ACES");
    addSpace(config, kWorkingColourSpace, {"lin_rec709", "scene_linear_rec709"},
             acesFromLinearRec709(), "Working");
    addSpace(config, "ACEScg", {}, builtin("ACEScg_to_ACES2065-1"), "ACES");
    for (const BuiltinCamera& c : kCameras)
        addSpace(config, c.name, {c.style}, builtin(c.style), "Camera");
    // BT.709's OETF: V = 1.099·L^0.45 − 0.099, 4.5·L below L = 0.018 (gamma 1/0.45).
    addSpace(config, "Rec.709 - Camera", {"Utility - Rec.709 - Camera", "rec709"},
             group({decodeCurve(1.0 / 0.45, 0.099), acesFromLinearRec709()}), "Camera");
    addSpace(config, "sRGB - Texture", {"sRGB", "srgb"},
             group({decodeCurve(2.4, 0.055), acesFromLinearRec709()}), "Camera");
    config->setRole(OCIO::ROLE_SCENE_LINEAR, kWorkingColourSpace);
    config->setRole(OCIO::ROLE_INTERCHANGE_SCENE, kInterchangeColourSpace);
    config->setRole(OCIO::ROLE_DEFAULT, kWorkingColourSpace);
    addDisplays(config);
    config->validate();
    return config;
}

}  // namespace

OCIO_NAMESPACE::ConstConfigRcPtr builtinColourConfig() {
    static const OCIO::ConstConfigRcPtr config = makeBuiltinConfig();
    return config;
}

std::vector<std::string> builtinCameraColourSpaces() {
    std::vector<std::string> names;
    for (const BuiltinCamera& c : kCameras) names.emplace_back(c.name);
    names.emplace_back("Rec.709 - Camera");
    names.emplace_back("sRGB - Texture");
    return names;
}

}  // namespace previs
