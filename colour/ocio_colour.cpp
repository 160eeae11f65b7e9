#include "colour/ocio_colour.h"

#include <OpenColorIO/OpenColorIO.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "base/log.h"
#include "colour/ocio_builtin_config.h"

namespace previs {

namespace OCIO = OCIO_NAMESPACE;

struct CameraColourTransform::Processors {
    OCIO::ConstCPUProcessorRcPtr from8;
    OCIO::ConstCPUProcessorRcPtr fromFloat;
};

struct DisplayColourTransform::Processors {
    OCIO::ConstCPUProcessorRcPtr toU8;
};

namespace {

// Names for a message: at most `most`, then how many there are in all.
std::string someNames(const std::vector<std::string>& names, size_t most = 16) {
    std::string out;
    for (size_t i = 0; i < names.size() && i < most; ++i)
        out += (i ? ", " : "") + ("\"" + names[i] + "\"");
    if (names.size() > most) out += fmt::format(", … ({} in all)", names.size());
    return out;
}

std::string configName(const OcioSource& source) {
    return source.configPath.empty() ? "OCIO's built-in transforms" : "'" + source.configPath + "'";
}

// How a message names the input and the config: a command line's option or the config's key.
std::string inputName(const OcioSource& source) {
    return source.inputOption.empty() ? "'" + source.key + ".input'" : source.inputOption;
}

std::string configKeyName(const OcioSource& source) {
    return source.configOption.empty() ? "'" + source.key + ".ocio_config'" : source.configOption;
}

Result<OCIO::ConstConfigRcPtr> loadConfig(const OcioSource& source) {
    if (source.configPath.empty()) return builtinColourConfig();
    // OCIO's own message for a missing file does not say which key named it.
    std::ifstream probe(source.configPath);
    if (!probe)
        return makeError(
            "{}: cannot read '{}' ({}); name a readable OCIO config "
            "file, or leave it out for the built-in camera transforms",
            configKeyName(source), source.configPath, std::strerror(errno));
    try {
        OCIO::ConstConfigRcPtr config = OCIO::Config::CreateFromFile(source.configPath.c_str());
        config->validate();
        return config;
    } catch (const std::exception& e) {
        return makeError("{}: '{}' is not a valid OCIO config: {}", configKeyName(source),
                         source.configPath, e.what());
    }
}

std::vector<std::string> sceneSpaces(const OCIO::ConstConfigRcPtr& config) {
    std::vector<std::string> names;
    for (int i = 0; i < config->getNumColorSpaces(); ++i) {
        const char* name = config->getColorSpaceNameByIndex(i);
        OCIO::ConstColorSpaceRcPtr cs = config->getColorSpace(name);
        if (cs && cs->getReferenceSpaceType() == OCIO::REFERENCE_SPACE_SCENE &&
            std::strcmp(cs->getFamily(), "Display") != 0)
            names.emplace_back(name);
    }
    return names;
}

Status checkInput(const OcioSource& source, const OCIO::ConstConfigRcPtr& config,
                  const std::string& input) {
    if (!input.empty() && config->getColorSpace(input.c_str())) return {};
    const std::vector<std::string> valid =
        source.configPath.empty() ? builtinCameraColourSpaces() : sceneSpaces(config);
    if (input.empty())
        return makeError("[{}] needs 'input', the camera's colour space in {}, e.g. {}", source.key,
                         configName(source), someNames(valid));
    return makeError("{} is '{}', not a colour space of {}; use one of {}", inputName(source),
                     input, configName(source), someNames(valid));
}

// A user's config reaches the working space through ACES2065-1 (its aces_interchange role).
Status checkInterchange(const OcioSource& source, const OCIO::ConstConfigRcPtr& config) {
    if (source.configPath.empty() || config->getColorSpace(OCIO::ROLE_INTERCHANGE_SCENE)) return {};
    return makeError(
        "{}: '{}' has no aces_interchange role, which previs needs to reach its "
        "working space (linear Rec.709); add 'aces_interchange: <its ACES2065-1 colour space>' "
        "to the config's roles",
        configKeyName(source), source.configPath);
}

OCIO::ConstProcessorRcPtr cameraProcessor(const OcioSource& source,
                                          const OCIO::ConstConfigRcPtr& config,
                                          const std::string& input) {
    if (source.configPath.empty()) return config->getProcessor(input.c_str(), kWorkingColourSpace);
    return OCIO::Config::GetProcessorFromConfigs(config, input.c_str(), builtinColourConfig(),
                                                 kWorkingColourSpace);
}

// Legal range's codes to the signal: v/255 → (v − 16)/219, as a matrix (OCIO's RangeTransform
// would clamp, and super-whites above 235 are picture).
OCIO::ConstProcessorRcPtr fromLegalRange(const OCIO::ConstProcessorRcPtr& processor) {
    constexpr double scale = 255.0 / 219.0, offset = -16.0 / 219.0;
    const std::array<double, 16> m{scale, 0, 0, 0, 0, scale, 0, 0, 0, 0, scale, 0, 0, 0, 0, 1};
    const std::array<double, 4> o{offset, offset, offset, 0};
    OCIO::MatrixTransformRcPtr legal = OCIO::MatrixTransform::Create();
    legal->setMatrix(m.data());
    legal->setOffset(o.data());
    OCIO::GroupTransformRcPtr all = OCIO::GroupTransform::Create();
    all->appendTransform(legal);
    all->appendTransform(processor->createGroupTransform());
    return builtinColourConfig()->getProcessor(all);
}

}  // namespace

CameraColourTransform::CameraColourTransform(std::unique_ptr<const Processors> processors,
                                             std::string description)
    : processors_(std::move(processors)), description_(std::move(description)) {}

CameraColourTransform::~CameraColourTransform() = default;

Result<std::shared_ptr<const CameraColourTransform>> CameraColourTransform::create(
    const OcioSource& source, const std::string& input, CodeRange range) {
    Result<OCIO::ConstConfigRcPtr> config = loadConfig(source);
    if (!config) return config.error();
    if (Status s = checkInput(source, *config, input); !s) return s.error();
    if (Status s = checkInterchange(source, *config); !s) return s.error();
    try {
        OCIO::ConstProcessorRcPtr processor = cameraProcessor(source, *config, input);
        if (range == CodeRange::Legal) processor = fromLegalRange(processor);
        auto p = std::make_unique<Processors>();
        // For 8-bit input OCIO folds the per-channel curve into a 256-entry table
        // (OPTIMIZATION_COMP_SEPARABLE_PREFIX): the matrix is all that is left per pixel.
        p->from8 = processor->getOptimizedCPUProcessor(OCIO::BIT_DEPTH_UINT8, OCIO::BIT_DEPTH_F32,
                                                       OCIO::OPTIMIZATION_DEFAULT);
        p->fromFloat = processor->getOptimizedCPUProcessor(OCIO::OPTIMIZATION_DEFAULT);
        const std::string description =
            fmt::format("'{}' from {}{}", input, configName(source),
                        range == CodeRange::Legal ? ", legal range (16-235)" : "");
        return std::shared_ptr<const CameraColourTransform>(
            new CameraColourTransform(std::move(p), description));
    } catch (const std::exception& e) {
        return makeError("{} '{}' in {}: OCIO cannot build its transform: {}", inputName(source),
                         input, configName(source), e.what());
    }
}

void CameraColourTransform::apply8(const uint8_t* src, std::ptrdiff_t srcStrideBytes, float* dst,
                                   std::ptrdiff_t dstStrideBytes, int width, int height) const {
    if (width <= 0 || height <= 0) return;  // OCIO refuses an empty image (by throwing)
    const OCIO::PackedImageDesc in(const_cast<uint8_t*>(src), width, height, 3,
                                   OCIO::BIT_DEPTH_UINT8, 1, 3, srcStrideBytes);
    OCIO::PackedImageDesc out(dst, width, height, 3, OCIO::BIT_DEPTH_F32, 4, 12, dstStrideBytes);
    processors_->from8->apply(in, out);
}

void CameraColourTransform::applyFloat(float* rgb, int width, int height,
                                       std::ptrdiff_t strideBytes) const {
    if (width <= 0 || height <= 0) return;  // OCIO refuses an empty image (by throwing)
    OCIO::PackedImageDesc image(rgb, width, height, 3, OCIO::BIT_DEPTH_F32, 4, 12, strideBytes);
    processors_->fromFloat->apply(image);
}

namespace {

std::vector<std::string> displaysOf(const OCIO::ConstConfigRcPtr& config) {
    std::vector<std::string> names;
    for (int i = 0; i < config->getNumDisplays(); ++i) names.emplace_back(config->getDisplay(i));
    return names;
}

std::vector<std::string> viewsOf(const OCIO::ConstConfigRcPtr& config, const std::string& display) {
    std::vector<std::string> names;
    for (int i = 0; i < config->getNumViews(display.c_str()); ++i)
        names.emplace_back(config->getView(display.c_str(), i));
    return names;
}

bool contains(const std::vector<std::string>& names, const std::string& name) {
    for (const std::string& n : names)
        if (n == name) return true;
    return false;
}

// The display and view, the config's defaults for those not named; an error lists what exists.
Status resolveDisplayView(const OcioSource& source, const OCIO::ConstConfigRcPtr& config,
                          std::string& display, std::string& view) {
    if (display.empty()) display = config->getDefaultDisplay();
    const std::vector<std::string> displays = displaysOf(config);
    if (!contains(displays, display))
        return makeError("'{}.display' is '{}', not a display of {}; use one of {}", source.key,
                         display, configName(source), someNames(displays));
    if (view.empty()) view = config->getDefaultView(display.c_str());
    const std::vector<std::string> views = viewsOf(config, display);
    if (!contains(views, view))
        return makeError("'{}.view' is '{}', not a view of the display '{}' in {}; use one of {}",
                         source.key, view, display, configName(source), someNames(views));
    return {};
}

// Working space → the view. A user's config is entered at its aces_interchange colour space.
OCIO::ConstProcessorRcPtr displayProcessor(const OcioSource& source,
                                           const OCIO::ConstConfigRcPtr& config,
                                           const std::string& display, const std::string& view) {
    OCIO::DisplayViewTransformRcPtr dv = OCIO::DisplayViewTransform::Create();
    dv->setDisplay(display.c_str());
    dv->setView(view.c_str());
    if (source.configPath.empty()) {
        dv->setSrc(kWorkingColourSpace);
        return config->getProcessor(dv);
    }
    const char* aces = config->getColorSpace(OCIO::ROLE_INTERCHANGE_SCENE)->getName();
    dv->setSrc(aces);
    OCIO::ConstProcessorRcPtr toAces = OCIO::Config::GetProcessorFromConfigs(
        builtinColourConfig(), kWorkingColourSpace, config, aces);
    OCIO::GroupTransformRcPtr all = OCIO::GroupTransform::Create();
    all->appendTransform(toAces->createGroupTransform());
    all->appendTransform(config->getProcessor(dv)->createGroupTransform());
    return config->getProcessor(all);
}

// The curve alone, per channel of the working space: a view that is separable there (an
// un-tone-mapped one) stays separable, and the LUT interpolates along each axis only.
OCIO::BuiltinTransformRcPtr acescctToLinear() {
    OCIO::BuiltinTransformRcPtr logToLinear = OCIO::BuiltinTransform::Create();
    logToLinear->setStyle("CURVE - ACEScct-LOG_to_LINEAR");
    return logToLinear;
}

// A view's output transform can be ~100 operations a pixel (ACES 1.0's: 170 ms a 1280×720
// frame on a 2-core box), too slow for a live monitor. It is sampled once on a grid over
// ACEScct's log curve and applied as that curve and a tetrahedral 3D LUT (on the host here, or
// on the device: DisplayColourTransform::lut).
// The view sampled on the grid's nodes (DisplayColourTransform::kLutSize³ over ACEScct).
std::vector<float> viewTable(const OCIO::ConstProcessorRcPtr& view) {
    const size_t n = DisplayColourTransform::kLutSize;
    // The grid's nodes in ACEScct, red fastest.
    std::vector<float> rgb(n * n * n * 3);
    for (size_t b = 0; b < n; ++b)
        for (size_t g = 0; g < n; ++g)
            for (size_t r = 0; r < n; ++r) {
                float* p = &rgb[3 * ((b * n + g) * n + r)];
                p[0] = float(r) / float(n - 1);
                p[1] = float(g) / float(n - 1);
                p[2] = float(b) / float(n - 1);
            }
    OCIO::PackedImageDesc grid(rgb.data(), long(n * n * n), 1, 3);
    builtinColourConfig()->getProcessor(acescctToLinear())->getDefaultCPUProcessor()->apply(grid);
    view->getDefaultCPUProcessor()->apply(grid);
    return rgb;
}

// The table applied as OCIO does it: the ACEScct curve, then the tetrahedral 3D LUT.
OCIO::ConstProcessorRcPtr tableProcessor(const std::vector<float>& table) {
    const size_t n = DisplayColourTransform::kLutSize;
    OCIO::Lut3DTransformRcPtr lut = OCIO::Lut3DTransform::Create(n);
    lut->setInterpolation(OCIO::INTERP_TETRAHEDRAL);
    for (size_t b = 0; b < n; ++b)
        for (size_t g = 0; g < n; ++g)
            for (size_t r = 0; r < n; ++r) {
                const float* p = &table[3 * ((b * n + g) * n + r)];
                lut->setValue(r, g, b, p[0], p[1], p[2]);
            }
    OCIO::GroupTransformRcPtr baked = OCIO::GroupTransform::Create();
    OCIO::TransformRcPtr linearToLog = acescctToLinear()->createEditableCopy();
    linearToLog->setDirection(OCIO::TRANSFORM_DIR_INVERSE);
    baked->appendTransform(linearToLog);
    baked->appendTransform(lut);
    return builtinColourConfig()->getProcessor(baked);
}

}  // namespace

DisplayColourTransform::DisplayColourTransform(std::unique_ptr<const Processors> processors,
                                               std::shared_ptr<const std::vector<float>> lut,
                                               std::string description)
    : processors_(std::move(processors)),
      lut_(std::move(lut)),
      description_(std::move(description)) {}

DisplayColourTransform::~DisplayColourTransform() = default;

Result<std::shared_ptr<const DisplayColourTransform>> DisplayColourTransform::create(
    const OcioSource& source, const std::string& displayName, const std::string& viewName) {
    Result<OCIO::ConstConfigRcPtr> config = loadConfig(source);
    if (!config) return config.error();
    std::string display = displayName, view = viewName;
    if (Status s = resolveDisplayView(source, *config, display, view); !s) return s.error();
    if (Status s = checkInterchange(source, *config); !s) return s.error();
    try {
        auto lut = std::make_shared<const std::vector<float>>(
            viewTable(displayProcessor(source, *config, display, view)));
        OCIO::ConstProcessorRcPtr processor = tableProcessor(*lut);
        auto p = std::make_unique<Processors>();
        p->toU8 = processor->getOptimizedCPUProcessor(OCIO::BIT_DEPTH_F32, OCIO::BIT_DEPTH_UINT8,
                                                      OCIO::OPTIMIZATION_DEFAULT);
        const std::string description =
            fmt::format("display '{}', view '{}' from {}", display, view, configName(source));
        return std::shared_ptr<const DisplayColourTransform>(
            new DisplayColourTransform(std::move(p), std::move(lut), description));
    } catch (const std::exception& e) {
        return makeError("[{}] display '{}', view '{}' in {}: OCIO cannot build the transform: {}",
                         source.key, display, view, configName(source), e.what());
    }
}

void DisplayColourTransform::apply(const float* rgb, int width, int height, uint8_t* out) const {
    if (width <= 0 || height <= 0) return;  // OCIO refuses an empty image (by throwing)
    const OCIO::PackedImageDesc in(const_cast<float*>(rgb), width, height, 3, OCIO::BIT_DEPTH_F32,
                                   4, 12, ptrdiff_t(width) * 12);
    OCIO::PackedImageDesc dst(out, width, height, 3, OCIO::BIT_DEPTH_UINT8, 1, 3,
                              ptrdiff_t(width) * 3);
    processors_->toU8->apply(in, dst);
}

void DisplayColourTransform::applyScaled(float* pixels, int channels, int width, int height,
                                         const std::array<float, 3>& gain, uint8_t* out) const {
    const size_t count = size_t(width) * size_t(height);
    PV_ASSERT(channels >= 3);
    const size_t stride = size_t(channels);
    // Pixel i is written at 3·i ≤ stride·i: never ahead of a pixel not yet read.
    for (size_t i = 0; i < count; ++i)
        for (size_t c = 0; c < 3; ++c) pixels[3 * i + c] = pixels[stride * i + c] * gain[c];
    apply(pixels, width, height, out);
}

}  // namespace previs

namespace previs {

namespace {

// The FileTransforms' sources of `transform` and its groups' children.
void collectFileSources(const OCIO::ConstTransformRcPtr& transform,
                        std::vector<std::string>& sources) {
    if (!transform) return;
    if (auto file = OCIO::DynamicPtrCast<const OCIO::FileTransform>(transform)) {
        sources.emplace_back(file->getSrc());
    } else if (auto group = OCIO::DynamicPtrCast<const OCIO::GroupTransform>(transform)) {
        for (int i = 0; i < group->getNumTransforms(); ++i)
            collectFileSources(group->getTransform(i), sources);
    }
}

// Every transform a config holds: its colour spaces' (active or not), looks', view transforms'
// and named transforms', both directions.
std::vector<std::string> fileSources(const OCIO::ConstConfigRcPtr& config) {
    std::vector<std::string> sources;
    const int spaces =
        config->getNumColorSpaces(OCIO::SEARCH_REFERENCE_SPACE_ALL, OCIO::COLORSPACE_ALL);
    for (int i = 0; i < spaces; ++i) {
        OCIO::ConstColorSpaceRcPtr cs = config->getColorSpace(config->getColorSpaceNameByIndex(
            OCIO::SEARCH_REFERENCE_SPACE_ALL, OCIO::COLORSPACE_ALL, i));
        if (!cs) continue;
        collectFileSources(cs->getTransform(OCIO::COLORSPACE_DIR_TO_REFERENCE), sources);
        collectFileSources(cs->getTransform(OCIO::COLORSPACE_DIR_FROM_REFERENCE), sources);
    }
    for (int i = 0; i < config->getNumLooks(); ++i) {
        OCIO::ConstLookRcPtr look = config->getLook(config->getLookNameByIndex(i));
        collectFileSources(look->getTransform(), sources);
        collectFileSources(look->getInverseTransform(), sources);
    }
    for (int i = 0; i < config->getNumViewTransforms(); ++i) {
        OCIO::ConstViewTransformRcPtr vt =
            config->getViewTransform(config->getViewTransformNameByIndex(i));
        collectFileSources(vt->getTransform(OCIO::VIEWTRANSFORM_DIR_TO_REFERENCE), sources);
        collectFileSources(vt->getTransform(OCIO::VIEWTRANSFORM_DIR_FROM_REFERENCE), sources);
    }
    for (int i = 0; i < config->getNumNamedTransforms(OCIO::NAMEDTRANSFORM_ALL); ++i) {
        OCIO::ConstNamedTransformRcPtr nt = config->getNamedTransform(
            config->getNamedTransformNameByIndex(OCIO::NAMEDTRANSFORM_ALL, i));
        collectFileSources(nt->getTransform(OCIO::TRANSFORM_DIR_FORWARD), sources);
        collectFileSources(nt->getTransform(OCIO::TRANSFORM_DIR_INVERSE), sources);
    }
    return sources;
}

Result<OCIO::ConstConfigRcPtr> readConfigFile(const std::string& configPath) {
    try {
        return OCIO::Config::CreateFromFile(configPath.c_str());
    } catch (const std::exception& e) {
        return makeError("'{}' is not a valid OCIO config: {}", configPath, e.what());
    }
}

}  // namespace

Result<std::vector<std::string>> ocioConfigFiles(const std::string& configPath) {
    Result<OCIO::ConstConfigRcPtr> config = readConfigFile(configPath);
    if (!config) return config.error();
    OCIO::ConstContextRcPtr context = (*config)->getCurrentContext();
    std::vector<std::string> files;
    for (const std::string& source : fileSources(*config)) {
        std::string resolved;
        try {
            resolved = context->resolveFileLocation(source.c_str());
        } catch (const std::exception&) {
            continue;  // not found: fails when used, as without a take
        }
        resolved = std::filesystem::absolute(resolved).lexically_normal().string();
        if (std::find(files.begin(), files.end(), resolved) == files.end())
            files.push_back(resolved);
    }
    return files;
}

Result<std::string> relocatableOcioConfig(const std::string& configPath) {
    Result<OCIO::ConstConfigRcPtr> config = readConfigFile(configPath);
    if (!config) return config.error();
    const std::filesystem::path folder =
        std::filesystem::absolute(configPath).parent_path().lexically_normal();
    bool absolute = false;
    for (int i = 0; i < (*config)->getNumSearchPaths(); ++i)
        absolute |= std::filesystem::path((*config)->getSearchPath(i)).is_absolute();
    if (!absolute) {
        std::ifstream in(configPath, std::ios::binary);
        std::ostringstream bytes;
        bytes << in.rdbuf();
        if (!in) return makeError("cannot read '{}' ({})", configPath, std::strerror(errno));
        return bytes.str();
    }
    OCIO::ConfigRcPtr copy = (*config)->createEditableCopy();
    copy->clearSearchPaths();
    for (int i = 0; i < (*config)->getNumSearchPaths(); ++i) {
        const std::filesystem::path p((*config)->getSearchPath(i));
        copy->addSearchPath((p.is_absolute() ? p.lexically_normal().lexically_relative(folder) : p)
                                .string()
                                .c_str());
    }
    std::ostringstream text;
    try {
        copy->serialize(text);
    } catch (const std::exception& e) {
        return makeError("'{}': OCIO cannot write it with relative search paths: {}", configPath,
                         e.what());
    }
    return text.str();
}

}  // namespace previs
