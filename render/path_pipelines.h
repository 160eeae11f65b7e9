#pragma once

// The path tracer's pipeline variants: trace_paths and, where photons run, the photon passes
// (render/photon_map.h), specialised on the host for one set of feature constants
// (PV_SPEC_*; STYLE.md: code a scene does not use is compiled out). One owner decides when to
// compile and when to bind: ensure() compiles only for constants that differ from the current
// set's, and bind() binds only buffers that differ from the ones bound, so the renderer states
// what it needs each frame instead of tracking what went stale.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/compute_pipeline.h"
#include "gpu/context.h"
#include "gpu/shaders/shared/scene_types.h"
#include "render/photon_map.h"

namespace previs {

using PipelineConstants = std::array<uint32_t, PV_SPEC_COUNT>;

class PathPipelines {
public:
    PathPipelines(GpuContext& ctx, Specialise specialise) : ctx_(&ctx), specialise_(specialise) {}

    // Makes the set for `constants` current, compiling it when they differ from the current
    // set's or no complete set exists (a failed compile leaves none, so the next call compiles
    // again). PV_SPEC_PHOTONS adds the photon passes, which share trace_paths' scene layout.
    Status ensure(const PipelineConstants& constants);
    // Whether ensure(constants) has nothing to compile.
    bool current(const PipelineConstants& constants) const;
    // The pipelines a set for `constants` compiles (trace_paths, and the photon passes).
    static size_t pipelineCount(const PipelineConstants& constants);
    // Binds buffers[i] (ranges[i] of it) at binding i of every pipeline of the set, unless the
    // set has them bound already. Nothing to do without a set.
    Status bind(std::span<const GpuBuffer* const> buffers, std::span<const BufferRange> ranges);

    bool ready() const { return paths_.has_value(); }
    ComputePipeline& paths() { return *paths_; }
    PhotonPasses* photons() { return photons_ ? &*photons_ : nullptr; }
    // How often a set was compiled (RendererDiagnostics::pipelineCompileCount).
    uint64_t compileCount() const { return compiles_; }

private:
    Status compile(const PipelineConstants& constants);

    GpuContext* ctx_;
    Specialise specialise_;
    PipelineConstants constants_{};
    std::optional<ComputePipeline> paths_;
    std::optional<PhotonPasses> photons_;
    uint64_t compiles_ = 0;
    // What the current set has bound: each binding's buffer (GpuBuffer::id) and range (empty:
    // nothing).
    struct Bound {
        uint64_t buffer, offset, size;
        bool operator==(const Bound&) const = default;
    };
    std::vector<Bound> bound_;
};

}  // namespace previs
