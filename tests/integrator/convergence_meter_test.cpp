// The convergence meter on real renders: its estimate against the true error (a long reference
// render), rendering to a target noise, and the extremes of the trade — 1 and 10^6 samples per
// pixel, 64×64 and 3840×2160, max depth 1 and 64, a black scene, a 1e5-radiance sun — none of
// which may give a NaN, an infinity or a stuck ETA.
#include <gtest/gtest.h>

#include <cmath>

#include "render/convergence.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/images.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

// The honesty bound: estimate and truth within this factor of each other.
constexpr double kHonestyFactor = 1.5;

// A real floor and box under a real sun and sky, with virtual balls casting shadows onto the
// set and lighting it by interreflection: the signal differential rendering adds to the plate.
// With `glossy`, one ball is rough metal: it reflects the sun (a delta light) onto the floor, a
// glossy caustic whose paths are rare — the case a sample-based meter cannot see early (below).
Scene differentialSet(bool glossy = false) {
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 2}, {2, 0, 0}, addMaterial(s, lambert(glm::vec3(0.7f))), true);
    addBox(s, {-0.9f, 0, -0.3f}, {-0.5f, 0.4f, 0.1f},
           addMaterial(s, lambert(glm::vec3(0.8f, 0.1f, 0.1f))), true);
    addSphere(s, {0.3f, 0.35f, 0.0f}, 0.25f, addMaterial(s, lambert(glm::vec3(0.1f, 0.8f, 0.2f))),
              false, 16, 32);
    Material second = lambert(glm::vec3(0.9f));
    if (glossy) {
        second.metallic = 1.0f;
        second.roughness = 0.3f;
    }
    addSphere(s, {-0.2f, 0.2f, 0.5f}, 0.2f, addMaterial(s, second), false, 16, 32);
    s.lights.push_back(realSun(glm::vec3(-1, -1, 0.3f), 3.0f));
    s.environment = uniformEnvironment(glm::vec3(0.3f));
    s.cameras.push_back(lookAt({0, 2.2f, 1.2f}, {0, 0, 0}, {0, 1, 0}, glm::radians(60.0f)));
    return s;
}

// A smooth plate of moderate values (the meter adds its (1 − M)·L_oc per sample).
ImageF gradientPlate(uint32_t w, uint32_t h) {
    ImageF p = filledImage(w, h, 3);
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x)
            for (uint32_t c = 0; c < 3; ++c)
                p.pixels[(size_t(y) * w + x) * 3 + c] =
                    0.1f + 0.8f * float(x + y + 7 * c) / float(w + h + 14);
    return p;
}

RenderSettings meterSettings(uint32_t w, uint32_t h) {
    RenderSettings rs = renderSettings(w, h, 4);
    rs.differential = true;
    rs.samplesPerDispatch = 64;
    return rs;
}

// DESIGN §4's relMSE of `image` against `reference`.
double relMse(const std::vector<double>& image, const std::vector<double>& reference) {
    double sum = 0.0;
    for (size_t i = 0; i < image.size(); ++i) {
        const double d = image[i] - reference[i];
        sum += d * d / (reference[i] * reference[i] + kRelMseOffset);
    }
    return sum / double(image.size());
}

std::vector<double> values(const ImageF& image) {
    return std::vector<double>(image.pixels.begin(), image.pixels.end());
}

// L_om − L_or, per pixel and channel.
std::vector<double> differentialSignal(Renderer& r) {
    const ImageF mixed = r.image(Aov::Mixed).value();
    const ImageF real = r.image(Aov::Real).value();
    std::vector<double> d(mixed.pixels.size());
    for (size_t i = 0; i < d.size(); ++i) d[i] = double(mixed.pixels[i]) - real.pixels[i];
    return d;
}

class ConvergenceMeterTest : public GpuTest {
protected:
    // The converged images (8192 spp) and the meter's estimate of their own remaining error,
    // which the true error measured against them includes (E[(x − ref)²] = err_x² + err_ref²)
    // and is subtracted: 1/8 of the error at 1024 spp, a 6 % bias in the ratio otherwise.
    struct Reference {
        std::vector<double> composite, differential;
        double compositeNoise = 0.0, differentialNoise = 0.0;
    };
    static constexpr uint32_t kReferenceSpp = 8192;

    Reference reference(const Scene& scene, const RenderSettings& rs, const ImageF& plate) {
        Reference ref;
        auto r = Renderer::create(ctx(), scene, rs);
        EXPECT_TRUE(r.ok()) << r.message();
        if (!r) return ref;
        EXPECT_TRUE((*r)->film().setPlate(plate).ok());
        (*r)->setSeed(9001);
        EXPECT_TRUE((*r)->render(kReferenceSpp).ok());
        ref.composite = values((*r)->image().value());
        ref.differential = differentialSignal(**r);
        const Convergence c = (*r)->convergence().value();
        ref.compositeNoise = c.composite.relativeRmse.value_or(0.0);
        ref.differentialNoise = c.differential.relativeRmse.value_or(0.0);
        return ref;
    }
};

double trueError(double measuredRelMse, double referenceNoise) {
    return std::sqrt(std::max(measuredRelMse - referenceNoise * referenceNoise, 0.0));
}

// The estimate against the truth at 16, 64, 256 and 1024 spp, on the composite and on the
// differential signal, and rendering to a target noise lands within the same factor.
TEST_F(ConvergenceMeterTest, EstimateIsWithinOneAndAHalfOfTheTrueError) {
    const Scene scene = differentialSet();
    const RenderSettings rs = meterSettings(32, 32);
    const ImageF plate = gradientPlate(rs.width, rs.height);
    const Reference ref = reference(scene, rs, plate);
    ASSERT_FALSE(ref.composite.empty());

    auto created = Renderer::create(ctx(), scene, rs);
    ASSERT_TRUE(created.ok()) << created.message();
    Renderer& r = **created;
    ASSERT_TRUE(r.film().setPlate(plate).ok());
    r.setSeed(1);
    uint64_t done = 0;
    for (uint32_t spp : {16u, 64u, 256u, 1024u}) {
        ASSERT_TRUE(r.render(uint32_t(spp - done)).ok());
        done = spp;
        const Convergence c = r.convergence().value();
        ASSERT_TRUE(c.composite.relativeRmse && c.differential.relativeRmse);
        const double composite =
            trueError(relMse(values(r.image().value()), ref.composite), ref.compositeNoise);
        const double differential =
            trueError(relMse(differentialSignal(r), ref.differential), ref.differentialNoise);
        const double compositeRatio = *c.composite.relativeRmse / composite;
        const double differentialRatio = *c.differential.relativeRmse / differential;
        RecordProperty("composite_ratio_" + std::to_string(spp), std::to_string(compositeRatio));
        RecordProperty("differential_ratio_" + std::to_string(spp),
                       std::to_string(differentialRatio));
        EXPECT_LT(compositeRatio, kHonestyFactor) << spp << " spp";
        EXPECT_GT(compositeRatio, 1.0 / kHonestyFactor) << spp << " spp";
        EXPECT_LT(differentialRatio, kHonestyFactor) << spp << " spp";
        EXPECT_GT(differentialRatio, 1.0 / kHonestyFactor) << spp << " spp";
    }

    // Rendering to a target, as `previs render --target-noise` does.
    for (double target : {0.04, 0.015}) {
        ASSERT_TRUE(r.reset().ok());
        r.setSeed(77);
        NoiseSchedule schedule(target);
        while (!schedule.reached() && r.samplesPerPixel() < kReferenceSpp / 2) {
            ASSERT_TRUE(r.render(1).ok());
            if (schedule.due(r.samplesPerPixel()))
                schedule.looked(r.samplesPerPixel(),
                                r.convergence().value().composite.relativeRmse);
        }
        ASSERT_TRUE(schedule.reached()) << "target " << target;
        const double truth =
            trueError(relMse(values(r.image().value()), ref.composite), ref.compositeNoise);
        RecordProperty("target_" + std::to_string(target) + "_true",
                       std::to_string(truth) + " at " + std::to_string(r.samplesPerPixel()));
        EXPECT_LT(truth / target, kHonestyFactor) << "target " << target;
        EXPECT_GT(truth / target, 1.0 / kHonestyFactor) << "target " << target;
    }
}

// Is every pixel of every AOV finite?
void expectFinite(Renderer& r, const std::string& what) {
    for (Aov aov : {Aov::Composite, Aov::Mixed, Aov::Real, Aov::Mask}) {
        const ImageF image = r.image(aov).value();
        size_t bad = 0;
        for (float v : image.pixels) bad += !std::isfinite(v);
        EXPECT_EQ(bad, 0u) << what << ", AOV " << int(aov);
    }
    EXPECT_EQ(r.nonFiniteSamples().value(), 0u) << what;
}

// The meter's figures at an extreme: present from 2 spp on, finite, and an ETA that is finite
// and 0 once reached.
void expectMeterSane(Renderer& r, const std::string& what) {
    const Convergence c = r.convergence().value();
    if (r.samplesPerPixel() < 2) {
        EXPECT_FALSE(c.composite.relativeRmse) << what;
        return;
    }
    ASSERT_TRUE(c.composite.relativeRmse && c.differential.relativeRmse) << what;
    EXPECT_TRUE(std::isfinite(*c.composite.relativeRmse)) << what;
    EXPECT_TRUE(std::isfinite(*c.differential.relativeRmse)) << what;
    const std::optional<double> eta =
        secondsToStop(r.samplesPerPixel(), c.composite.relativeRmse, 0.01, 0, 1e-3);
    ASSERT_TRUE(eta) << what;
    EXPECT_TRUE(std::isfinite(*eta)) << what;
    EXPECT_GE(*eta, 0.0) << what;
}

// 1 spp (no estimate yet, an image all the same) and 2; max depth 1 and 64; 64×64.
TEST_F(ConvergenceMeterTest, ExtremesOfSamplesAndDepthStayFinite) {
    const Scene scene = differentialSet();
    for (uint32_t depth : {1u, 64u}) {
        RenderSettings rs = meterSettings(64, 64);
        rs.maxDepth = depth;
        auto r = Renderer::create(ctx(), scene, rs);
        ASSERT_TRUE(r.ok()) << r.message();
        ASSERT_TRUE((*r)->film().setPlate(gradientPlate(64, 64)).ok());
        for (uint32_t spp : {1u, 1u, 6u}) {
            ASSERT_TRUE((*r)->render(spp).ok());
            const std::string what = "depth " + std::to_string(depth) + ", " +
                                     std::to_string((*r)->samplesPerPixel()) + " spp";
            expectFinite(**r, what);
            expectMeterSane(**r, what);
        }
    }
}

// 10^6 samples in one pixel: the compensated sums keep the mean and the meter right, and the
// meter keeps falling as 1/√spp or faster.
TEST_F(ConvergenceMeterTest, AMillionSamplesPerPixel) {
    const Scene scene = differentialSet();
    RenderSettings rs = meterSettings(1, 1);
    rs.samplesPerDispatch = 4096;
    auto r = Renderer::create(ctx(), scene, rs);
    ASSERT_TRUE(r.ok()) << r.message();
    ASSERT_TRUE((*r)->film().setPlate(gradientPlate(1, 1)).ok());
    ASSERT_TRUE((*r)->render(1000).ok());
    const double at1000 = (*r)->convergence().value().composite.relativeRmse.value();
    ASSERT_TRUE((*r)->render(1000000 - 1000).ok());
    expectFinite(**r, "1e6 spp");
    expectMeterSane(**r, "1e6 spp");
    const double atMillion = (*r)->convergence().value().composite.relativeRmse.value();
    // One pixel: a one-degree-of-freedom estimate each, so only a loose bound (a χ²₁ ratio
    // above 10 has probability < 0.2 %): 1000× the samples, at least ~3× less noise.
    EXPECT_LT(atMillion, at1000 * 0.3);
}

// A black scene (no light at all) has zero variance: the meter says 0, exactly, and the ETA 0.
TEST_F(ConvergenceMeterTest, BlackSceneIsConvergedNotNaN) {
    Scene scene = differentialSet();
    scene.lights.clear();
    scene.environment.reset();
    RenderSettings rs = meterSettings(16, 16);
    rs.differential = false;
    auto r = Renderer::create(ctx(), scene, rs);
    ASSERT_TRUE(r.ok()) << r.message();
    ASSERT_TRUE((*r)->render(8).ok());
    const Convergence c = (*r)->convergence().value();
    ASSERT_TRUE(c.composite.relativeRmse);
    EXPECT_EQ(*c.composite.relativeRmse, 0.0);
    EXPECT_EQ(secondsToStop(8, c.composite.relativeRmse, 0.01, 0, 1e-3), 0.0);
}

// A pixel seeing a 1e5-radiance sun (a small emitter, as a real sun disc is): finite images and
// meter, and the sun pixel does not swamp the estimate (relMSE divides by its square).
TEST_F(ConvergenceMeterTest, SunOfRadianceOneHundredThousand) {
    Scene scene = differentialSet();
    addQuad(scene, {0.0f, 0.5f, -1.2f}, {0.02f, 0, 0}, {0, 0.02f, 0},
            addMaterial(scene, emitter(glm::vec3(1e5f))), true);
    RenderSettings rs = meterSettings(48, 48);
    auto r = Renderer::create(ctx(), scene, rs);
    ASSERT_TRUE(r.ok()) << r.message();
    ASSERT_TRUE((*r)->film().setPlate(gradientPlate(48, 48)).ok());
    ASSERT_TRUE((*r)->render(16).ok());
    expectFinite(**r, "sun");
    expectMeterSane(**r, "sun");
    const ImageF mixed = (*r)->image(Aov::Mixed).value();
    float brightest = 0.0f;
    for (float v : mixed.pixels) brightest = std::max(brightest, v);
    EXPECT_GT(brightest, 1e3f) << "the sun should be in view";
}

// 3840×2160: the accumulation (six vec4 sums and compensations per pixel, 1.6 GB) and the
// meter's readback work at UHD. Each image() and convergence() reads the whole accumulation back
// (about 10 CPU-s at this size), so the frame is read twice, not once an AOV: the composite over
// the plate (Eq. 1: the plate-free and mask slots) and the meter (every slot). The other AOVs are
// other slots' means of the same readback, checked finite at 64x64
// (ExtremesOfSamplesAndDepthStayFinite); no sample was dropped as non-finite here either.
TEST_F(ConvergenceMeterTest, UltraHdFrame) {
    const Scene scene = differentialSet();
    RenderSettings rs = meterSettings(3840, 2160);
    rs.maxDepth = 2;
    auto r = Renderer::create(ctx(), scene, rs);
    ASSERT_TRUE(r.ok()) << r.message();
    ASSERT_TRUE((*r)->film().setPlate(gradientPlate(3840, 2160)).ok());
    ASSERT_TRUE((*r)->render(2).ok());
    const ImageF composite = (*r)->image(Aov::Composite).value();
    EXPECT_EQ(composite.pixels.size(), size_t(3840) * 2160 * composite.channels);
    size_t bad = 0;
    for (float v : composite.pixels) bad += !std::isfinite(v);
    EXPECT_EQ(bad, 0u) << "3840x2160 composite";
    EXPECT_EQ((*r)->nonFiniteSamples().value(), 0u) << "3840x2160";
    expectMeterSane(**r, "3840x2160");
}

}  // namespace
}  // namespace previs::testing
