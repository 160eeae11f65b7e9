#include "display/frame_output.h"

#include "display/files_output.h"
#include "display/kms_output.h"

namespace previs {

Result<std::unique_ptr<FrameOutput>> makeFrameOutput(const OutputSettings& settings) {
    if (settings.kind == "none") return std::unique_ptr<FrameOutput>(new NoneOutput);
    if (settings.kind == "files") {
        auto out = FilesOutput::create(settings.folder, settings.files);
        if (!out) return out.error();
        return std::unique_ptr<FrameOutput>(std::move(*out));
    }
    if (settings.kind == "kms") {
        auto out = KmsOutput::create(settings);
        if (!out) return out.error();
        return std::unique_ptr<FrameOutput>(std::move(*out));
    }
    return makeError("[output] kind \"{}\": expected \"kms\", \"files\" or \"none\"",
                     settings.kind);
}

}  // namespace previs
