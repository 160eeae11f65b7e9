#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <numeric>

#include "gpu/buffer.h"
#include "gpu/compute_pipeline.h"
#include "gpu/context.h"
#include "gpu/spirv_specialise.h"
#include "specialise_probe.spv.h"

namespace previs {
namespace {

std::span<const uint32_t> probeSpirv() {
    return {specialise_probe_spv, sizeof(specialise_probe_spv) / 4};
}

// Opcodes of the module's instructions (SPIR-V: a 5-word header, then instructions whose first
// word holds the word count in the high half and the opcode in the low half).
std::vector<uint32_t> opcodes(std::span<const uint32_t> module) {
    std::vector<uint32_t> ops;
    for (size_t at = 5; at < module.size(); at += module[at] >> 16) {
        if ((module[at] >> 16) == 0) break;
        ops.push_back(module[at] & 0xffffu);
    }
    return ops;
}

constexpr uint32_t kOpFunction = 54;
constexpr uint32_t kOpSpecConstantTrue = 48;
constexpr uint32_t kOpSpecConstantOp = 52;

TEST(SpecialiseTest, FreezesConstantsAndDropsDisabledCode) {
    const std::array<uint32_t, 3> allOn{1, 1, 5};
    const std::array<uint32_t, 3> squareOff{1, 0, 5};
    auto on = specialiseSpirv(probeSpirv(), allOn);
    auto off = specialiseSpirv(probeSpirv(), squareOff);
    ASSERT_TRUE(on.ok()) << on.message();
    ASSERT_TRUE(off.ok()) << off.message();
    for (const auto* module : {&*on, &*off})
        for (uint32_t op : opcodes(*module))
            EXPECT_FALSE(op >= kOpSpecConstantTrue && op <= kOpSpecConstantOp)
                << "specialization constant left (opcode " << op << ")";
    auto functions = [](const std::vector<uint32_t>& m) {
        auto ops = opcodes(m);
        return std::count(ops.begin(), ops.end(), kOpFunction);
    };
    // main and squared(); with the switch off squared() is gone.
    EXPECT_EQ(functions(*on), 2);
    EXPECT_EQ(functions(*off), 1);
    EXPECT_LT(off->size(), probeSpirv().size());
}

TEST(SpecialiseTest, NotASpirvModuleIsAnError) {
    const std::array<uint32_t, 6> garbage{1, 2, 3, 4, 5, 6};
    auto result = specialiseSpirv(garbage, std::array<uint32_t, 1>{1});
    ASSERT_FALSE(result.ok());
    EXPECT_NE(result.message().find("SPIRV-Tools"), std::string::npos) << result.message();
}

// A module specialised on the host computes what the driver's own specialisation does, for every
// combination of the switches (the validation layer checks the module too).
TEST(SpecialiseTest, HostAndDriverSpecialisationAgree) {
    auto ctx = GpuContext::create({.validation = true, .deviceOverride = ""});
    ASSERT_TRUE(ctx.ok()) << ctx.message();
    std::vector<uint32_t> input(256);
    std::iota(input.begin(), input.end(), 0u);
    for (uint32_t doubleLarge : {0u, 1u})
        for (uint32_t square : {0u, 1u})
            for (uint32_t offset : {0u, 7u}) {
                const std::array<uint32_t, 3> constants{doubleLarge, square, offset};
                std::vector<uint32_t> results[2];
                const Specialise modes[2] = {Specialise::OnHost, Specialise::InDriver};
                for (int m = 0; m < 2; ++m) {
                    auto buffer =
                        GpuBuffer::createWith(**ctx, std::span<const uint32_t>(input), "values");
                    ASSERT_TRUE(buffer.ok()) << buffer.message();
                    const std::array<BindingKind, 1> kinds{BindingKind::StorageBuffer};
                    auto pipeline = ComputePipeline::create(**ctx, probeSpirv(), kinds, constants,
                                                            "specialise_probe", modes[m]);
                    ASSERT_TRUE(pipeline.ok()) << pipeline.message();
                    const GpuBuffer* bound[] = {&*buffer};
                    ASSERT_TRUE(pipeline->bind(bound).ok());
                    ASSERT_TRUE(pipeline->dispatch(uint32_t(input.size()) / 64, 1).ok());
                    results[m].resize(input.size());
                    ASSERT_TRUE(buffer->download(results[m].data(), input.size() * 4).ok());
                }
                for (uint32_t i = 0; i < input.size(); ++i) {
                    uint32_t v = doubleLarge && i > 3u ? 2u * i : i;
                    if (square) v *= v;
                    ASSERT_EQ(results[0][i], v + offset) << doubleLarge << square << offset;
                    ASSERT_EQ(results[1][i], v + offset) << doubleLarge << square << offset;
                }
            }
    EXPECT_EQ((*ctx)->validationErrorCount(), 0u);
}

// A pipeline made again from the same module, constants and bindings reuses the compile (a
// renderer made anew compiles nothing it compiled before), but keeps its own buffers: each of two
// such pipelines transforms the buffer bound to it, once. Other constants are another compile.
// Every pipeline made is counted for whoever waits for a batch (GpuContext::setCompileListener).
TEST(SpecialiseTest, PipelinesMadeAgainShareTheirCompileNotTheirBuffers) {
    auto ctx = GpuContext::create({.validation = true, .deviceOverride = ""});
    ASSERT_TRUE(ctx.ok()) << ctx.message();
    int made = 0;
    (*ctx)->setCompileListener([&made] { ++made; });
    const std::array<BindingKind, 1> kinds{BindingKind::StorageBuffer};
    const std::array<uint32_t, 3> squared{0, 1, 0}, offset{0, 0, 7};
    std::vector<uint32_t> input(64);
    std::iota(input.begin(), input.end(), 0u);
    std::vector<GpuBuffer> buffers;
    std::vector<ComputePipeline> pipelines;
    for (const auto* constants : {&squared, &squared, &offset}) {
        auto buffer = GpuBuffer::createWith(**ctx, std::span<const uint32_t>(input), "values");
        ASSERT_TRUE(buffer.ok()) << buffer.message();
        buffers.push_back(std::move(*buffer));
        auto pipeline =
            ComputePipeline::create(**ctx, probeSpirv(), kinds, *constants, "specialise_probe");
        ASSERT_TRUE(pipeline.ok()) << pipeline.message();
        pipelines.push_back(std::move(*pipeline));
    }
    EXPECT_EQ(made, 3);
    EXPECT_TRUE(pipelines[1].sharesCompileWith(pipelines[0]));
    EXPECT_FALSE(pipelines[2].sharesCompileWith(pipelines[0]));
    for (size_t p = 0; p < pipelines.size(); ++p) {
        const GpuBuffer* bound[] = {&buffers[p]};
        ASSERT_TRUE(pipelines[p].bind(bound).ok());
    }
    for (size_t p : {1u, 2u, 0u}) ASSERT_TRUE(pipelines[p].dispatch(1, 1).ok());
    for (size_t p = 0; p < pipelines.size(); ++p) {
        std::vector<uint32_t> got(input.size());
        ASSERT_TRUE(buffers[p].download(got.data(), got.size() * 4).ok());
        for (uint32_t i = 0; i < input.size(); ++i)
            ASSERT_EQ(got[i], p < 2 ? i * i : i + 7) << "pipeline " << p << ", value " << i;
    }
    pipelines.clear();
    (*ctx)->setCompileListener({});
    EXPECT_EQ((*ctx)->validationErrorCount(), 0u);
}

// Pipelines nothing uses are kept for reuse, the 16 most recently asked for; those in use always.
TEST(SpecialiseTest, AContextKeepsOnlyTheRecentPipelinesNothingUses) {
    auto ctx = GpuContext::create({.validation = true, .deviceOverride = ""});
    ASSERT_TRUE(ctx.ok()) << ctx.message();
    const std::array<BindingKind, 1> kinds{BindingKind::StorageBuffer};
    std::vector<ComputePipeline> inUse;
    for (uint32_t offset = 0; offset < 24; ++offset) {
        const std::array<uint32_t, 3> constants{0, 0, offset};
        auto pipeline = ComputePipeline::create(**ctx, probeSpirv(), kinds, constants, "probe");
        ASSERT_TRUE(pipeline.ok()) << pipeline.message();
        if (offset < 4) inUse.push_back(std::move(*pipeline));
    }
    // The 4 in use, the last one made, and the 16 most recent of the 19 between, unused when it
    // was compiled (the 3 oldest dropped then).
    EXPECT_EQ(compiledPipelinesKept(**ctx), 21u);
    inUse.clear();
    EXPECT_EQ((*ctx)->validationErrorCount(), 0u);
}

}  // namespace
}  // namespace previs
