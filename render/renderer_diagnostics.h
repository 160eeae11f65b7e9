#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "base/result.h"
#include "gpu/shaders/shared/photon_records.h"

namespace previs {

class Renderer;

// Probes into a renderer's inner state for tests and benchmarks, kept out of its API
// (Renderer::diagnostics()). Valid while the renderer lives.
class RendererDiagnostics {
public:
    explicit RendererDiagnostics(const Renderer& renderer) : r_(renderer) {}

    // How often the renderer built its BVH and geometry buffers (1: only in create()).
    uint64_t sceneBuildCount() const;
    // How often it made its pipelines (each compiled, or reused from the context's compile of
    // the same: ComputePipeline::create): 1 after create() where the constants it predicts
    // before the BVH is built held, 2 where the uploaded scene (GpuScene) found otherwise.
    uint64_t pipelineCompileCount() const;
    // How often the GPU's origin moved since create() (Renderer::setCameraPose).
    uint64_t recentreCount() const;
    // The last photon iteration's records (two per photon, PV_PHOTON_* flags; empty slots have
    // flags 0).
    Result<std::vector<shader::PhotonRecord>> photonRecords() const;
    // The last photon iteration's grid as the gather reads it: the records sorted by bucket,
    // each bucket's [begin, end) in them (PV_PHOTON_BUCKETS), and the iteration's radius (the
    // cell edge).
    struct PhotonGrid {
        std::vector<shader::PhotonRecord> sorted;
        std::vector<glm::uvec2> buckets;
        float radius = 0.0f;
    };
    Result<PhotonGrid> photonGrid() const;
    // Dispatches whose loop iterations may have reached llvmpipe's limit (work silently lost);
    // 0 unless RendererTestOptions::respectCpuLoopLimit was off or one sample alone is too long.
    uint64_t loopLimitRisks() const;
    // The most loop iterations one invocation ran per sample (the dispatch sizing measure;
    // measured on CPU devices only, 0 elsewhere).
    double loopIterationsPerSample() const;

private:
    const Renderer& r_;
};

}  // namespace previs
