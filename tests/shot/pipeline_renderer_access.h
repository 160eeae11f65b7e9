#pragma once

// The inner renderer of a PipelineRenderer, for tests that check its state or drive it directly
// (the dial's pan, the held view's floor): PipelineRenderer hands it to no one else (issue 55).

#include "render/renderer.h"
#include "shot/pipeline_renderer.h"

namespace previs {

struct PipelineRendererAccess {
    static Renderer& renderer(PipelineRenderer& p) { return *p.renderer_; }
};

namespace testing {

inline Renderer& innerRenderer(PipelineRenderer& p) { return PipelineRendererAccess::renderer(p); }

}  // namespace testing
}  // namespace previs
