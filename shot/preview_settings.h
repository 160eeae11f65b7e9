#pragma once

// Preview's settings (issue 55: one holder, PipelineRenderer): what a preview frame traces and
// how it is denoised, as the config, the dial, a reload and the 3-second cap set them.

#include <cstdint>

namespace previs {

struct PreviewSettings {
    uint32_t samplesPerFrame = 1;
    float resolutionScale = 1.0f;  // refinement always traces every pixel
    uint32_t maxDepth = 8;         // refinement traces [render] max_depth
    uint32_t denoiseLevels = 0;    // à-trous levels; 0: not denoised
    uint32_t photons = 0;          // per preview frame, where the photon pass runs

    bool operator==(const PreviewSettings&) const = default;
};

// The settings configured (the config's, the dial's choice, a reload's samples) and those in use:
// the configured ones, with fewer samples where the cap lowered them (ShotController).
struct PreviewState {
    PreviewSettings configured;
    PreviewSettings inUse;
};

}  // namespace previs
