#include "render/renderer_diagnostics.h"

#include "render/renderer.h"

namespace previs {

uint64_t RendererDiagnostics::sceneBuildCount() const { return r_.sceneBuilds_; }
uint64_t RendererDiagnostics::pipelineCompileCount() const { return r_.pipelines_->compileCount(); }
uint64_t RendererDiagnostics::recentreCount() const { return r_.scene_->recentreCount(); }
uint64_t RendererDiagnostics::loopLimitRisks() const { return r_.loopLimitRisks_; }
double RendererDiagnostics::loopIterationsPerSample() const { return r_.loopIterationsPerSample_; }

Result<std::vector<shader::PhotonRecord>> RendererDiagnostics::photonRecords() const {
    std::vector<shader::PhotonRecord> records(size_t(PV_PHOTON_RECORDS_PER_PHOTON) *
                                              r_.lastPhotonCount_);
    if (Status s = r_.buffers_->photonRecords.download(
            records.data(), records.size() * sizeof(shader::PhotonRecord));
        !s)
        return s.error();
    return records;
}

Result<RendererDiagnostics::PhotonGrid> RendererDiagnostics::photonGrid() const {
    PhotonGrid grid;
    grid.sorted.resize(size_t(PV_PHOTON_RECORDS_PER_PHOTON) * r_.lastPhotonCount_);
    grid.buckets.resize(PV_PHOTON_BUCKETS);
    grid.radius = r_.params_.photonRadius;
    if (Status s = r_.buffers_->photonSorted.download(
            grid.sorted.data(), grid.sorted.size() * sizeof(shader::PhotonRecord));
        !s)
        return s.error();
    if (Status s = r_.buffers_->photonCells.download(grid.buckets.data(),
                                                     grid.buckets.size() * sizeof(glm::uvec2));
        !s)
        return s.error();
    return grid;
}

}  // namespace previs
