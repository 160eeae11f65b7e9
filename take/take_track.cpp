#include "take/take_track.h"

#include "base/log.h"
#include "capture/recorded_source.h"
#include "shot/pipeline_stages.h"
#include "vision/track_smoother.h"

namespace previs {

Result<TakeTrack> trackTake(const SessionInfo& session, const ServiceConfig& config,
                            const TrackProgress& progress) {
    const SessionCamera* scene = session.cameraWithRole("scene");
    if (!scene) return makeError("{}: the take has no scene camera (cameras/scene)", session.dir);
    TakeTrack track;
    Result<std::vector<RecordedFrameEntry>> entries =
        loadCameraIndex(scene->dir, &track.skippedLines);
    if (!entries) return entries.error();
    Result<TrackingStage> tracking = TrackingStage::create(config);
    if (!tracking) return tracking.error();

    std::vector<TrackSample> samples;
    for (RecordedFrameEntry& e : *entries) {
        TakeFrame f;
        f.entry = std::move(e);
        TrackSample sample;
        sample.timestampNs = f.entry.timestampNs;
        Result<Frame> decoded = readRecordedFrame(f.entry);
        if (!decoded) {
            f.problem = decoded.message();
        } else {
            const TrackedFrame t =
                tracking->process(std::make_shared<const Frame>(std::move(*decoded)));
            if (t.trackedWorldFromCamera) {
                f.tracked = t.trackedWorldFromCamera;
                f.tags = t.tags;
                f.reprojErrorPx = t.reprojErrorPx;
                f.positionStdM = t.positionStdM;
                f.rotationStdDeg = t.rotationStdDeg;
                sample.worldFromCamera = t.trackedWorldFromCamera;
                sample.positionStdM = t.positionStdM;
                sample.rotationStdDeg = t.rotationStdDeg;
            }
        }
        samples.push_back(sample);
        track.frames.push_back(std::move(f));
        if (progress) progress(track.frames.size(), entries->size());
    }
    const std::vector<std::optional<cv::Matx44d>> smoothed = smoothTrack(samples);
    for (size_t i = 0; i < track.frames.size(); ++i) track.frames[i].smoothed = smoothed[i];
    return track;
}

}  // namespace previs
