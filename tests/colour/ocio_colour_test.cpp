// Camera and display colour through OpenColorIO (colour/ocio_colour.h).

#include "colour/ocio_colour.h"

#include <OpenColorIO/OpenColorIO.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>

#include "colour/ocio_builtin_config.h"
#include "vision/inverse_tone_map.h"

namespace previs {
namespace {

namespace OCIO = OCIO_NAMESPACE;
namespace fs = std::filesystem;

const OcioSource kBuiltin{"", "cameras.scene.colour"};

std::shared_ptr<const CameraColourTransform> camera(const std::string& space,
                                                    const OcioSource& source = kBuiltin) {
    Result<std::shared_ptr<const CameraColourTransform>> t =
        CameraColourTransform::create(source, space);
    EXPECT_TRUE(t) << (t ? "" : t.message());
    return t ? *t : nullptr;
}

// Working space → the camera's code values, by OCIO's own processor (the reference).
std::array<float, 3> encode(const std::string& space, std::array<float, 3> linear) {
    builtinColourConfig()
        ->getProcessor(kWorkingColourSpace, space.c_str())
        ->getDefaultCPUProcessor()
        ->applyRGB(linear.data());
    return linear;
}

std::array<float, 3> decode(const CameraColourTransform& t, std::array<float, 3> code) {
    t.applyFloat(code.data(), 1, 1, sizeof code);
    return code;
}

// 18 % grey's code value as each maker publishes it (full range, normalised), with the
// publication's own rounding as the tolerance.
struct PublishedGrey {
    const char* space;
    double code;
    double tolerance;
};
const std::array<PublishedGrey, 7> kPublishedGreys{{
    // ARRI, "ALEXA Log C Curve – Usage in VFX": EI800, 18 % grey at 0.391.
    {"ARRI LogC3 (EI800)", 0.391, 0.0005},
    // Sony, "Technical Summary for S-Gamut3.Cine/S-Log3 and S-Gamut3/S-Log3": code 420 of 1023.
    {"Sony S-Log3 S-Gamut3", 420.0 / 1023.0, 0.5 / 1023.0},
    // Panasonic, "V-Log/V-Gamut Reference Manual": 18 % at 0.423 (code 433 of 1023).
    {"Panasonic V-Log V-Gamut", 0.423, 0.0005},
    // RED, "REDWideGamutRGB and Log3G10" white paper: 18 % grey at 1/3.
    {"RED Log3G10 REDWideGamutRGB", 1.0 / 3.0, 0.0005},
    // Canon's input transforms (C300 Mk II, 2016/2020): 18 % reflectance at 0.398 (Canon Log 2)
    // and 0.343 (Canon Log 3) of full range; colour-science's log_encoding_CanonLog2/3 agree.
    {"Canon Log 2 Cinema Gamut", 0.398, 0.0005},
    {"Canon Log 3 Cinema Gamut", 0.343, 0.0005},
    // ITU-R BT.709 OETF: 1.099 · 0.18^0.45 − 0.099.
    {"Rec.709 - Camera", 1.099 * std::pow(0.18, 0.45) - 0.099, 1e-5},
}};

TEST(OcioCameraCurves, EncodeEighteenPercentGreyToThePublishedCode) {
    for (const PublishedGrey& g : kPublishedGreys) {
        const std::array<float, 3> code = encode(g.space, {0.18f, 0.18f, 0.18f});
        for (float c : code) EXPECT_NEAR(c, g.code, g.tolerance) << g.space;
    }
}

TEST(OcioCameraCurves, DecodeThePublishedGreyCodeToEighteenPercent) {
    for (const PublishedGrey& g : kPublishedGreys) {
        const std::shared_ptr<const CameraColourTransform> t = camera(g.space);
        ASSERT_TRUE(t);
        const float code = float(g.code);
        const std::array<float, 3> linear = decode(*t, {code, code, code});
        // The publication's rounding, carried through the curve's slope at grey.
        const float up = decode(*t, {code + float(g.tolerance), code, code})[0];
        const float slopeTolerance = std::abs(up - linear[0]) + 2e-4f;
        for (float v : linear) EXPECT_NEAR(v, 0.18f, slopeTolerance) << g.space;
    }
}

TEST(OcioCameraCurves, TheBuiltinTransformsStyleNamesTheSameSpace) {
    const auto byName = camera("ARRI LogC3 (EI800)");
    const auto byStyle = camera("ARRI_ALEXA-LOGC-EI800-AWG_to_ACES2065-1");
    ASSERT_TRUE(byName && byStyle);
    const std::array<float, 3> a = decode(*byName, {0.6f, 0.4f, 0.2f});
    const std::array<float, 3> b = decode(*byStyle, {0.6f, 0.4f, 0.2f});
    for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(a[c], b[c]);
}

// Video levels (issue 54): black at code 16 and white at 235, each of R, G, B; codes outside
// are kept (a super-white is picture), through the 8-bit path and the float one alike.
TEST(OcioCameraRange, LegalRangeMapsSixteenToBlackAndTwoThirtyFiveToWhiteWithoutClipping) {
    Result<std::shared_ptr<const CameraColourTransform>> legal =
        CameraColourTransform::create(kBuiltin, kWorkingColourSpace, CodeRange::Legal);
    ASSERT_TRUE(legal) << legal.message();
    EXPECT_NE((*legal)->description().find("legal range"), std::string::npos);
    const std::array<uint8_t, 6> codes{0, 8, 16, 126, 235, 255};
    std::vector<uint8_t> rgb8;
    std::vector<float> asFloats;
    for (uint8_t c : codes) {
        rgb8.insert(rgb8.end(), {c, c, c});
        asFloats.insert(asFloats.end(), {c / 255.0f, c / 255.0f, c / 255.0f});
    }
    std::vector<float> linear(rgb8.size());
    (*legal)->apply8(rgb8.data(), std::ptrdiff_t(rgb8.size()), linear.data(),
                     std::ptrdiff_t(linear.size() * sizeof(float)), int(codes.size()), 1);
    (*legal)->applyFloat(asFloats.data(), int(codes.size()), 1,
                         std::ptrdiff_t(asFloats.size() * sizeof(float)));
    for (size_t i = 0; i < codes.size(); ++i)
        for (int c = 0; c < 3; ++c) {
            const float expected = (float(codes[i]) - 16.0f) / 219.0f;  // 16 → 0, 235 → 1
            EXPECT_NEAR(linear[3 * i + c], expected, 1e-5f) << int(codes[i]);
            EXPECT_NEAR(asFloats[3 * i + c], expected, 1e-5f) << int(codes[i]);
        }
}

TEST(OcioCameraRange, ALegalRec709CameraKeepsItsSuperWhitesAboveDiffuseWhite) {
    const auto full = camera("Rec.709 - Camera");
    Result<std::shared_ptr<const CameraColourTransform>> legal =
        CameraColourTransform::create(kBuiltin, "Rec.709 - Camera", CodeRange::Legal);
    ASSERT_TRUE(full && legal) << (legal ? "" : legal.message());
    // Legal 16 and 235 are the full-range curve's 0 and 1.
    EXPECT_NEAR(decode(**legal, {16 / 255.0f, 16 / 255.0f, 16 / 255.0f})[0], 0.0f, 1e-5f);
    EXPECT_NEAR(decode(**legal, {235 / 255.0f, 235 / 255.0f, 235 / 255.0f})[0],
                decode(*full, {1.0f, 1.0f, 1.0f})[0], 1e-5f);
    // 255 is (255 − 16)/219 = 1.091 of the signal: the BT.709 OETF inverted there, above 1.
    const float superWhite = decode(**legal, {1.0f, 1.0f, 1.0f})[1];
    EXPECT_NEAR(superWhite, std::pow((239.0f / 219.0f + 0.099f) / 1.099f, 1.0f / 0.45f), 1e-4f);
    EXPECT_GT(superWhite, 1.15f);
}

// Truth in the working space: greys from 0.01 to `brightest` and a few colours a set has.
std::vector<std::array<float, 3>> truthPixels(float brightest) {
    std::vector<std::array<float, 3>> pixels;
    for (float g = 0.01f; g < brightest; g *= 1.25f) pixels.push_back({g, g, g});
    for (const std::array<float, 3>& c : std::vector<std::array<float, 3>>{
             {0.40f, 0.18f, 0.05f}, {0.05f, 0.10f, 0.50f}, {0.8f, 0.6f, 0.3f}, {0.1f, 0.3f, 0.1f}})
        pixels.push_back(c);
    if (brightest > 2.0f) pixels.push_back({2.0f, 1.0f, 0.5f});
    return pixels;
}

// How far an 8-bit quantisation can move a decoded pixel: the decoded value's largest change
// over the corners of the ±½ code cube around the exact code.
std::array<float, 3> quantisationBound(const CameraColourTransform& t,
                                       const std::array<float, 3>& code) {
    const std::array<float, 3> centre = decode(t, code);
    std::array<float, 3> bound{0.0f, 0.0f, 0.0f};
    for (int corner = 0; corner < 8; ++corner) {
        std::array<float, 3> moved = code;
        for (int c = 0; c < 3; ++c) moved[c] += ((corner >> c) & 1 ? 0.5f : -0.5f) / 255.0f;
        const std::array<float, 3> d = decode(t, moved);
        for (int c = 0; c < 3; ++c) bound[c] = std::max(bound[c], std::abs(d[c] - centre[c]));
    }
    return bound;
}

TEST(OcioCameraPath, AnEightBitLogFrameLinearisesWithinItsQuantisation) {
    for (const char* space :
         {"ARRI LogC3 (EI800)", "Sony S-Log3 S-Gamut3", "Panasonic V-Log V-Gamut",
          "RED Log3G10 REDWideGamutRGB", "Canon Log 3 Cinema Gamut", "Rec.709 - Camera"}) {
        InverseToneMapSettings radiometry;
        radiometry.colour = camera(space);
        ASSERT_TRUE(radiometry.colour);
        // A log curve keeps several stops over diffuse white; Rec.709 clips at 1.
        const bool log = std::string(space) != "Rec.709 - Camera";
        const std::vector<std::array<float, 3>> truth = truthPixels(log ? 6.0f : 0.95f);
        cv::Mat frame(1, int(truth.size()), CV_8UC3);
        std::vector<std::array<float, 3>> codes;
        for (size_t i = 0; i < truth.size(); ++i) {
            std::array<float, 3> code = encode(space, truth[i]);
            for (int c = 0; c < 3; ++c) {
                ASSERT_LT(code[c], 1.0f) << space << ": the truth must be encodable";
                frame.at<cv::Vec3b>(0, int(i))[c] = uint8_t(std::lround(code[c] * 255.0f));
            }
            codes.push_back(code);
        }
        const cv::Mat linear = inverseToneMapRgb8(frame, radiometry);
        for (size_t i = 0; i < truth.size(); ++i) {
            const std::array<float, 3> bound = quantisationBound(*radiometry.colour, codes[i]);
            for (int c = 0; c < 3; ++c)
                EXPECT_NEAR(linear.at<cv::Vec3f>(0, int(i))[c], truth[i][c],
                            bound[c] * 1.01f + 1e-5f * (1.0f + truth[i][c]))
                    << space << ", pixel " << i << ", channel " << c;
        }
    }
}

TEST(OcioCameraPath, ExposureAndWhiteBalanceApplyAfterTheCurve) {
    InverseToneMapSettings plain, calibrated;
    plain.colour = calibrated.colour = camera("Sony S-Log3 S-Gamut3");
    ASSERT_TRUE(plain.colour);
    calibrated.exposureStops = 1.0f;
    calibrated.whiteBalance = {2.0f, 1.0f, 0.5f};
    cv::Mat frame(2, 3, CV_8UC3, cv::Scalar(90, 105, 120));
    const cv::Mat a = inverseToneMapRgb8(frame, plain);
    const cv::Mat b = inverseToneMapRgb8(frame, calibrated);
    for (int c = 0; c < 3; ++c)
        EXPECT_FLOAT_EQ(b.at<cv::Vec3f>(1, 2)[c],
                        a.at<cv::Vec3f>(1, 2)[c] * 0.5f * calibrated.whiteBalance[c]);
    // The single-pixel path agrees with the frame's.
    const std::array<float, 3> one =
        inverseToneMapRgb({90 / 255.0f, 105 / 255.0f, 120 / 255.0f}, calibrated);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(one[c], b.at<cv::Vec3f>(0, 0)[c], 1e-4f);
}

TEST(OcioCameraPath, ARegionOfAFrameKeepsItsRowStride) {
    InverseToneMapSettings radiometry;
    radiometry.colour = camera("Panasonic V-Log V-Gamut");
    ASSERT_TRUE(radiometry.colour);
    cv::Mat frame(8, 16, CV_8UC3);
    cv::randu(frame, 0, 255);
    const cv::Mat whole = inverseToneMapRgb8(frame, radiometry);
    const cv::Rect inner(3, 2, 9, 5);
    const cv::Mat part = inverseToneMapRgb8(frame(inner), radiometry);
    EXPECT_EQ(cv::norm(part, whole(inner), cv::NORM_INF), 0.0);
}

TEST(OcioCameraPath, AnEmptyFrameIsNoWork) {
    InverseToneMapSettings radiometry;
    radiometry.colour = camera("Sony S-Log3 S-Gamut3");
    ASSERT_TRUE(radiometry.colour);
    EXPECT_TRUE(inverseToneMapRgb8(cv::Mat(0, 0, CV_8UC3), radiometry).empty());
    Result<std::shared_ptr<const DisplayColourTransform>> view =
        DisplayColourTransform::create({"", "output.colour"}, "", "");
    ASSERT_TRUE(view) << view.message();
    (*view)->apply(nullptr, 0, 0, nullptr);  // OCIO itself would throw on a 0×0 image
}

// A user's config: two colour spaces, the interchange role and a display.
fs::path writeConfig(const std::string& name, const std::string& roles) {
    const fs::path path = fs::temp_directory_path() / name;
    std::ofstream(path)
        << "ocio_profile_version: 2.1\n"
        << "roles:\n"
        << roles << "  default: ACES2065-1\n"
        << "displays:\n"
        << "  Studio monitor:\n"
        << "    - !<View> {name: Plain, colorspace: srgb display}\n"
        << "colorspaces:\n"
        << "  - !<ColorSpace>\n"
        << "    name: ACES2065-1\n"
        << "  - !<ColorSpace>\n"
        << "    name: A camera LogC\n"
        << "    to_scene_reference: !<BuiltinTransform> "
           "{style: ARRI_ALEXA-LOGC-EI800-AWG_to_ACES2065-1}\n"
        << "  - !<ColorSpace>\n"
        << "    name: srgb display\n"
        << "    from_scene_reference: !<GroupTransform> {children: [\n"
        << "      !<BuiltinTransform> {style: UTILITY - ACES-AP0_to_CIE-XYZ-D65_BFD},\n"
        << "      !<BuiltinTransform> {style: DISPLAY - CIE-XYZ-D65_to_sRGB}]}\n";
    return path;
}

TEST(OcioUserConfig, ACameraSpaceOfTheUsersConfigMatchesTheBuiltinOne) {
    const fs::path path = writeConfig("previs_ocio_user.ocio", "  aces_interchange: ACES2065-1\n");
    const auto user = camera("A camera LogC", {path.string(), "cameras.scene.colour"});
    const auto builtin = camera("ARRI LogC3 (EI800)");
    ASSERT_TRUE(user && builtin);
    for (float v : {0.1f, 0.391f, 0.55f}) {
        const std::array<float, 3> a = decode(*user, {v, v * 0.9f, v * 1.1f});
        const std::array<float, 3> b = decode(*builtin, {v, v * 0.9f, v * 1.1f});
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], b[c], 1e-4f * (1.0f + b[c]));
    }
    fs::remove(path);
}

std::vector<uint8_t> showGreys(const DisplayColourTransform& t, const std::vector<float>& greys) {
    std::vector<float> rgb;
    for (float g : greys) rgb.insert(rgb.end(), {g, g, g});
    std::vector<uint8_t> out(rgb.size());
    t.apply(rgb.data(), int(greys.size()), 1, out.data());
    return out;
}

float srgbEncode(float linear) {
    return linear <= 0.0031308f ? 12.92f * linear : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
}

TEST(OcioDisplay, UntoneMappedSrgbIsTheSrgbEncoding) {
    Result<std::shared_ptr<const DisplayColourTransform>> t =
        DisplayColourTransform::create({"", "output.colour"}, "sRGB", "Un-tone-mapped");
    ASSERT_TRUE(t) << t.message();
    const std::vector<float> greys{0.0f, 0.01f, 0.18f, 0.5f, 1.0f, 4.0f};
    const std::vector<uint8_t> shown = showGreys(**t, greys);
    for (size_t i = 0; i < greys.size(); ++i) {
        const float expected = 255.0f * srgbEncode(std::min(greys[i], 1.0f));
        EXPECT_NEAR(shown[3 * i], expected, 1.0f) << greys[i];
    }
}

TEST(OcioDisplay, TheDefaultViewRollsHighlightsOffInsteadOfClipping) {
    Result<std::shared_ptr<const DisplayColourTransform>> t =
        DisplayColourTransform::create({"", "output.colour"}, "", "");
    ASSERT_TRUE(t) << t.message();
    EXPECT_NE((*t)->description().find("ACES 1.0 - SDR Video"), std::string::npos);
    const std::vector<uint8_t> shown = showGreys(**t, {0.18f, 1.0f, 4.0f, 8.0f});
    EXPECT_LT(shown[0], shown[3]);
    EXPECT_LT(shown[3], shown[6]);
    EXPECT_LT(shown[6], shown[9]);
    EXPECT_LT(shown[6], 255) << "4.0, two stops over white, still has detail";
}

TEST(OcioDisplay, TheBakedViewMatchesOcioExactWithinACodeValue) {
    Result<std::shared_ptr<const DisplayColourTransform>> t =
        DisplayColourTransform::create({"", "output.colour"}, "sRGB", "ACES 1.0 - SDR Video");
    ASSERT_TRUE(t) << t.message();
    OCIO::DisplayViewTransformRcPtr dv = OCIO::DisplayViewTransform::Create();
    dv->setSrc(kWorkingColourSpace);
    dv->setDisplay("sRGB");
    dv->setView("ACES 1.0 - SDR Video");
    const OCIO::ConstCPUProcessorRcPtr exact =
        builtinColourConfig()->getProcessor(dv)->getDefaultCPUProcessor();
    // Colours from deep shadow to four stops over white whose channels lie within two stops of
    // each other (saturations a set shows; far out-of-gamut colours, channels 5+ stops apart,
    // land a few codes off: the ACES view bends hard there, between the grid's nodes).
    cv::RNG rng(54);
    const int count = 4096;
    std::vector<float> rgb(size_t(count) * 3);
    for (int i = 0; i < count; ++i) {
        const double stops = rng.uniform(-10.0, 4.0);
        for (int c = 0; c < 3; ++c)
            rgb[3 * i + c] = float(std::exp2(stops + rng.uniform(-1.0, 1.0)));
    }
    std::vector<uint8_t> shown(rgb.size());
    (*t)->apply(rgb.data(), count, 1, shown.data());
    int worst = 0;
    for (int i = 0; i < count; ++i) {
        std::array<float, 3> reference{rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]};
        exact->applyRGB(reference.data());
        for (int c = 0; c < 3; ++c) {
            const float code = 255.0f * std::clamp(reference[c], 0.0f, 1.0f);
            worst = std::max(worst, int(std::ceil(std::abs(shown[3 * i + c] - code) - 0.5f)));
        }
    }
    EXPECT_LE(worst, 1) << "8-bit codes off the exact view";
}

TEST(OcioDisplay, ARendersRgbaImageIsShownWithItsGainsUndone) {
    Result<std::shared_ptr<const DisplayColourTransform>> t =
        DisplayColourTransform::create({"", "output.colour"}, "sRGB", "Un-tone-mapped");
    ASSERT_TRUE(t) << t.message();
    // Two RGBA pixels; the gains are what PipelineRenderer passes: 2^exposure / white balance.
    std::vector<float> rgba{0.09f, 0.18f, 0.36f, 1.0f, 0.02f, 0.5f, 0.25f, 0.0f};
    const std::array<float, 3> gain{2.0f, 1.0f, 0.5f};
    std::vector<uint8_t> shown(6);
    (*t)->applyScaled(rgba.data(), 4, 2, 1, gain, shown.data());
    const std::vector<uint8_t> expected = showGreys(**t, {0.18f, 0.04f});
    EXPECT_EQ(shown[0], expected[0]);
    EXPECT_EQ(shown[1], expected[1]);
    EXPECT_EQ(shown[2], expected[2]);
    EXPECT_EQ(shown[3], expected[3]);
    EXPECT_NEAR(shown[4], 255.0f * srgbEncode(0.5f), 1.0f);
    EXPECT_NEAR(shown[5], 255.0f * srgbEncode(0.125f), 1.0f);
}

TEST(OcioDisplay, AUsersConfigIsEnteredAtItsInterchangeSpace) {
    const fs::path path =
        writeConfig("previs_ocio_display.ocio", "  aces_interchange: ACES2065-1\n");
    Result<std::shared_ptr<const DisplayColourTransform>> user =
        DisplayColourTransform::create({path.string(), "output.colour"}, "", "");
    Result<std::shared_ptr<const DisplayColourTransform>> builtin =
        DisplayColourTransform::create({"", "output.colour"}, "sRGB", "Un-tone-mapped");
    ASSERT_TRUE(user && builtin) << (user ? builtin.message() : user.message());
    const std::vector<float> greys{0.02f, 0.18f, 0.7f};
    const std::vector<uint8_t> a = showGreys(**user, greys), b = showGreys(**builtin, greys);
    for (size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1) << i;
    fs::remove(path);
}

std::string cameraError(const OcioSource& source, const std::string& input) {
    Result<std::shared_ptr<const CameraColourTransform>> t =
        CameraColourTransform::create(source, input);
    return t ? std::string("(no error)") : t.message();
}

TEST(OcioErrors, AnUnknownCameraSpaceNamesTheKeyAndListsValidOnes) {
    const std::string m = cameraError(kBuiltin, "LogC");
    EXPECT_NE(m.find("'cameras.scene.colour.input' is 'LogC'"), std::string::npos) << m;
    EXPECT_NE(m.find("\"ARRI LogC3 (EI800)\""), std::string::npos) << m;
    EXPECT_NE(m.find("\"Sony S-Log3 S-Gamut3\""), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << "one line";
    const std::string empty = cameraError(kBuiltin, "");
    EXPECT_NE(empty.find("needs 'input'"), std::string::npos) << empty;
}

TEST(OcioErrors, AnUnreadableConfigNamesTheFileAndTheKey) {
    const std::string m = cameraError({"/nonexistent/studio.ocio", "cameras.fisheye.colour"}, "x");
    EXPECT_NE(m.find("'cameras.fisheye.colour.ocio_config'"), std::string::npos) << m;
    EXPECT_NE(m.find("cannot read '/nonexistent/studio.ocio'"), std::string::npos) << m;

    const fs::path broken = fs::temp_directory_path() / "previs_ocio_broken.ocio";
    std::ofstream(broken) << "this: is: not an OCIO config\n";
    const std::string b = cameraError({broken.string(), "cameras.scene.colour"}, "x");
    EXPECT_NE(b.find("is not a valid OCIO config"), std::string::npos) << b;
    fs::remove(broken);
}

TEST(OcioErrors, AUserSpaceNotInTheConfigAndAMissingInterchangeRole) {
    const fs::path path = writeConfig("previs_ocio_norole.ocio", "");
    const OcioSource source{path.string(), "cameras.scene.colour"};
    const std::string unknown = cameraError(source, "LogC3");
    EXPECT_NE(unknown.find("\"A camera LogC\""), std::string::npos) << unknown;
    const std::string role = cameraError(source, "A camera LogC");
    EXPECT_NE(role.find("has no aces_interchange role"), std::string::npos) << role;
    fs::remove(path);
}

TEST(OcioErrors, AnUnknownDisplayOrViewListsThoseThatExist) {
    Result<std::shared_ptr<const DisplayColourTransform>> d =
        DisplayColourTransform::create({"", "output.colour"}, "P3", "");
    ASSERT_FALSE(d);
    EXPECT_NE(d.message().find("'output.colour.display' is 'P3'"), std::string::npos)
        << d.message();
    EXPECT_NE(d.message().find("\"Rec.1886 Rec.709\""), std::string::npos) << d.message();
    Result<std::shared_ptr<const DisplayColourTransform>> v =
        DisplayColourTransform::create({"", "output.colour"}, "sRGB", "Filmic");
    ASSERT_FALSE(v);
    EXPECT_NE(v.message().find("\"ACES 1.0 - SDR Video\""), std::string::npos) << v.message();
}

}  // namespace
}  // namespace previs
