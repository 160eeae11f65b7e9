// The monitor's frame made on the device (Renderer::display, render/display_pass.h) against the
// host's: the float composite (Renderer::image) tone mapped by toDisplayImage. The two run the
// same steps (upsampling, the held view's blend, Eq. 1, the curve, the 8-bit encode: one
// definition each in shared/composite.h, or the same table) and differ only by float rounding (the
// host sums in double): a value on a code's edge can land on either side. So at most one code
// apart, and on one value in a thousand at most.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>

#include "colour/ocio_colour.h"
#include "render/display_pass.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

constexpr uint32_t kSize = 64;

// How far two 8-bit frames are apart: the largest and the mean difference of a code.
struct CodeDifference {
    int largest = 0;
    double mean = 0.0;
};

CodeDifference compare(const DisplayImage& a, const DisplayImage& b) {
    EXPECT_EQ(a.width, b.width);
    EXPECT_EQ(a.height, b.height);
    CodeDifference d;
    if (a.rgb.size() != b.rgb.size() || a.rgb.empty()) return {255, 255.0};
    for (size_t i = 0; i < a.rgb.size(); ++i) {
        const int diff = std::abs(int(a.rgb[i]) - int(b.rgb[i]));
        d.largest = std::max(d.largest, diff);
        d.mean += diff;
    }
    d.mean /= double(a.rgb.size());
    return d;
}

// The camera curves the service meets: sRGB with a white balance to undo, and the demo's
// reinhard-extended with an exposure.
std::vector<DisplaySettings> curves() {
    DisplaySettings srgb;
    srgb.whiteBalance = {1.2f, 1.0f, 0.8f};
    DisplaySettings banterle;
    banterle.tone.op = ToneMapOperator::ReinhardExtended;
    banterle.tone.exposureStops = 0.5f;
    banterle.tone.maxRadiance = 8.0f;
    banterle.tone.whiteLuminance = 4.0f;
    return {srgb, banterle};
}

class DisplayTest : public GpuTest {
protected:
    std::unique_ptr<Renderer> make(float scale, bool denoise = false) {
        RenderSettings rs = renderSettings(kSize, kSize, 4);
        rs.differential = true;
        rs.samplesPerDispatch = 8;
        rs.resolutionScale = scale;
        rs.denoise = denoise;
        auto r = Renderer::create(ctx(), scene_, rs);
        EXPECT_TRUE(r.ok()) << r.message();
        if (!r) return nullptr;
        // The plate: the real-only solution with a checker, so the range kernel sees edges.
        EXPECT_TRUE((*r)->render(8).ok());
        Result<ImageF> real = (*r)->image(Aov::Real);
        EXPECT_TRUE(real.ok());
        ImageF plate = *real;
        for (size_t i = 0; i < plate.pixels.size(); ++i)
            plate.pixels[i] *= ((i / 3 % kSize / 8 + i / 3 / kSize / 8) % 2) ? 1.0f : 0.3f;
        EXPECT_TRUE((*r)->film().setPlate(plate).ok());
        EXPECT_TRUE((*r)->reset().ok());
        return std::move(*r);
    }

    void expectClose(Renderer& r, bool denoised) {
        for (const DisplaySettings& s : curves()) {
            Result<DisplayImage> device = r.display(denoised, s);
            ASSERT_TRUE(device.ok()) << device.message();
            Result<ImageF> host = r.image(Aov::Composite, denoised);
            ASSERT_TRUE(host.ok()) << host.message();
            const CodeDifference d = compare(*device, toDisplayImage(*host, s));
            EXPECT_LE(d.largest, 1) << int(s.tone.op);
            EXPECT_LE(d.mean, 1e-3) << int(s.tone.op);
        }
    }

    // A bright sky: values beyond 1 reach the curve's shoulder.
    const Scene scene_ = ballOnRealFloor(glm::vec3(3.0f));
};

TEST_F(DisplayTest, AtFullResolutionTheDeviceFrameIsTheHostFrameToOneCode) {
    auto r = make(1.0f);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->render(4).ok());
    expectClose(*r, false);
}

TEST_F(DisplayTest, UpsampledTheDeviceFrameIsTheHostFrameToOneCode) {
    for (float scale : {0.5f, 1.0f / 3.0f}) {
        auto r = make(scale);
        ASSERT_TRUE(r);
        ASSERT_TRUE(r->render(4).ok());
        expectClose(*r, false);
    }
}

TEST_F(DisplayTest, DenoisedTheDeviceFrameIsTheHostFrame) {
    auto r = make(0.5f, /*denoise=*/true);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->render(4).ok());
    expectClose(*r, true);
}

// Through the temporal stage each frame joins the history, so the device's and the host's frames
// come from two identical renderers fed the same frames.
TEST_F(DisplayTest, AccumulatedTheDeviceFrameIsTheHostFrame) {
    auto device = make(0.5f, /*denoise=*/true);
    auto host = make(0.5f, /*denoise=*/true);
    ASSERT_TRUE(device && host);
    const DisplaySettings s = curves()[1];
    for (uint64_t frame = 1; frame <= 3; ++frame) {
        for (Renderer* r : {device.get(), host.get()}) {
            r->film().setTemporalDenoise(true);
            ASSERT_TRUE(r->renderPreviewFrame(2, frame).ok());
        }
        Result<DisplayImage> shown = device->display(true, s);
        Result<ImageF> composite = host->image(Aov::Composite, true);
        ASSERT_TRUE(shown.ok() && composite.ok());
        const CodeDifference d = compare(*shown, toDisplayImage(*composite, s));
        EXPECT_LE(d.largest, 1) << frame;
        EXPECT_LE(d.mean, 1e-3) << frame;
    }
    EXPECT_EQ(device->film().denoiser()->historyFrames(), 3u);
}

// The held view's samples add up on the device over the frames it holds, and both sides blend
// the same sums.
TEST_F(DisplayTest, AHeldViewShowsItsKeptSamples) {
    // At a half and at a third (not a whole fraction: an output pixel on a traced pixel's edge
    // keeps only its owner's samples).
    for (float scale : {0.5f, 1.0f / 3.0f}) {
        auto r = make(scale);
        ASSERT_TRUE(r);
        for (uint64_t frame = 1; frame <= 3; ++frame) {
            ASSERT_TRUE(r->holdView(true).ok());
            ASSERT_TRUE(r->renderPreviewFrame(2, frame).ok());
        }
        EXPECT_EQ(r->film().heldFrames(), 3u);
        expectClose(*r, false);
        // Against a frame without the held view: the kept samples change the picture.
        Result<DisplayImage> held = r->display(false, curves()[0]);
        ASSERT_TRUE(r->holdView(false).ok());
        Result<DisplayImage> unheld = r->display(false, curves()[0]);
        ASSERT_TRUE(held.ok() && unheld.ok());
        EXPECT_GT(compare(*held, *unheld).mean, 0.01) << scale;
    }
}

// [output.colour]'s display and view on the device (DisplaySettings::viewLut) against the
// host's: the float composite, the same gains, through OCIO's processor of the same table
// (DisplayColourTransform::applyScaled). Both interpolate the same 65³ nodes; they differ by
// float rounding (the device's log2 and its interpolation against OCIO's), so a value on a
// code's edge can land on either side: at most one code apart, on one value in a thousand.
TEST_F(DisplayTest, ThroughADisplaysViewTheDeviceFrameIsOcioOnTheHostToOneCode) {
    Result<std::shared_ptr<const DisplayColourTransform>> view =
        DisplayColourTransform::create({"", "output.colour"}, "sRGB", "ACES 1.0 - SDR Video");
    ASSERT_TRUE(view) << view.message();
    for (float scale : {1.0f, 0.5f}) {
        auto r = make(scale);
        ASSERT_TRUE(r);
        ASSERT_TRUE(r->render(4).ok());
        for (DisplaySettings s : curves()) {
            s.viewLut = (*view)->lut();
            s.viewLutSize = DisplayColourTransform::kLutSize;
            Result<DisplayImage> device = r->display(false, s);
            ASSERT_TRUE(device.ok()) << device.message();
            Result<ImageF> host = r->image(Aov::Composite);
            ASSERT_TRUE(host.ok()) << host.message();
            std::array<float, 3> gain;
            for (int c = 0; c < 3; ++c)
                gain[c] = std::exp2(s.tone.exposureStops) / s.whiteBalance[c];
            DisplayImage shown{host->width, host->height,
                               std::vector<uint8_t>(size_t(host->width) * host->height * 3)};
            (*view)->applyScaled(host->pixels.data(), int(host->channels), int(host->width),
                                 int(host->height), gain, shown.rgb.data());
            const CodeDifference d = compare(*device, shown);
            EXPECT_LE(d.largest, 1) << scale;
            EXPECT_LE(d.mean, 1e-3) << scale;
            // Not the curve's frame: the view is what the device showed.
            Result<DisplayImage> curve = r->display(false, curves()[0]);
            ASSERT_TRUE(curve.ok());
            EXPECT_GT(compare(*device, *curve).mean, 1.0) << scale;
        }
    }
}

}  // namespace
}  // namespace previs::testing
