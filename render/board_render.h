#pragma once

// Camera images with exact ground truth for the tracker (issue: "pose accuracy on images with
// known ground truth"): a tag board rendered by the path tracer through a calibrated lens at a
// known camera pose, then degraded as a camera would (optical blur, sensor noise, 8-bit sRGB).
// Used by `previs bench --only pose` and tests/vision/rendered_pose_test.cpp.

#include <cstdint>
#include <glm/glm.hpp>
#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "base/result.h"
#include "gpu/context.h"
#include "image/image.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "vision/camera_calibration.h"
#include "vision/tag_board.h"

namespace previs {

// How the printed board looks. Its surfaces emit their albedo and nothing else lights the
// scene, so a pixel is exactly the box-filtered albedo under it: the image of a uniformly lit
// matte print at unit exposure, without shading or noise from the light transport.
struct BoardAppearance {
    float paperAlbedo = 0.8f;  // matte white paper
    float inkAlbedo = 0.04f;   // laser toner
    // Texture resolution. The shader filters textures bilinearly; bit edges fall on texel edges,
    // so the filter only spreads an edge over one texel symmetrically about its true position.
    uint32_t texelsPerBit = 16;
    double marginM = 0.02;  // white paper beyond the outermost tags' white border
};

// A 2-D grid of tags on the world plane z = 0, readable from +Z (world +Y is up the print),
// centred on the origin: ids firstId, firstId+1, … row by row from the top left.
Result<TagBoard> gridBoard(int columns, int rows, double tagSizeM, double pitchM,
                           const std::string& family = "tag36h11", int firstId = 0);

// The reference board of the pose tests and the sweep: an A2 poster (594×420 mm) carrying 4×3
// tag36h11 tags, 100 mm black squares at 140 mm pitch, ids 0–11.
TagBoard posterBoard();

// The board of the ViSP RBT video (../shared/data/video/README.md): 4×3 tag36h11 tags of
// 95.5 mm, ids 0–11, at 120 mm pitch, the tags turned 90° against the board's axes.
TagBoard vispRbtBoard();

// The board as a scene: one textured quad per tag (its bitmap from libapriltag, white border
// included) in front of a white backing plane. All tags must lie on one plane.
Result<Scene> tagBoardScene(const TagBoard& board, const std::string& family,
                            const BoardAppearance& appearance = {});

// A path tracer loaded with a board scene and a calibrated lens (primary rays follow the lens
// model: vision/lens_grid.h), re-rendered at any camera pose.
class BoardRenderer {
public:
    // Renders at the calibration's image size with `spp` jittered samples per pixel (the box
    // pixel filter antialiases the edges).
    static Result<BoardRenderer> create(GpuContext& ctx, const TagBoard& board,
                                        const std::string& family,
                                        const CameraCalibration& calibration, uint32_t spp,
                                        const BoardAppearance& appearance = {});

    // Linear radiance, one channel, of the board seen from `worldFromCameraCv` (OpenCV frame).
    // `seed` selects the antialiasing jitter's random sequence.
    Result<ImageF> render(const cv::Matx44d& worldFromCameraCv, uint32_t seed = 0);

private:
    BoardRenderer(std::unique_ptr<Renderer> renderer, uint32_t spp)
        : renderer_(std::move(renderer)), spp_(spp) {}

    std::unique_ptr<Renderer> renderer_;
    uint32_t spp_;
};

// The camera's transfer curve from radiance to code values.
enum class TransferCurve {
    Srgb,    // what webcams and most video cameras deliver
    Linear,  // gamma 1 (machine-vision cameras): code = 255 × radiance
};

// What the camera does after the lens.
struct Degradation {
    double blurSigmaPx = 0.0;       // Gaussian optical blur (defocus, lens), pixels; 0 = none
    double noiseSigmaLevels = 0.0;  // additive Gaussian noise on the 8-bit code values
    uint64_t seed = 1;              // of the noise
    TransferCurve curve = TransferCurve::Srgb;
};

// Linear grey radiance → the 8-bit grey frame the tracker receives: blur in linear light (optics
// act on radiance), the transfer curve, noise on the code values, rounding and clipping.
cv::Mat toCameraGray8(const ImageF& linear, const Degradation& degradation);

// Where a camera looks at the board centre (the world origin) from.
struct BoardView {
    double distanceM = 1.0;   // camera centre to board centre
    double angleDeg = 0.0;    // between the line of sight to the board centre and the board normal
    double azimuthDeg = 0.0;  // direction of that tilt about the normal (0: camera toward +X)
    double rollDeg = 0.0;     // about the optical axis
    // Turns the camera about its own y axis, so the board centre is seen this far off the
    // optical axis (where the lens distorts more).
    double offAxisDeg = 0.0;
};

// worldFromCamera in OpenCV's camera frame for a board on the plane z = 0 readable from +Z.
cv::Matx44d cameraViewingBoard(const BoardView& view);

struct CameraPoseError {
    double translationM = 0.0;  // distance between the estimated and true camera centres
    double rotationDeg = 0.0;   // angle of R_estᵀ·R_true
};

CameraPoseError cameraPoseError(const cv::Matx44d& estimatedWorldFromCamera,
                                const cv::Matx44d& trueWorldFromCamera);

}  // namespace previs
