#include "render/board_render.h"

#include <apriltag/apriltag.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagStandard41h12.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "base/log.h"
#include "render/tonemap.h"
#include "vision/lens_grid.h"

namespace previs {

namespace {

constexpr double kPi = 3.14159265358979323846;

struct FamilyDeleter {
    void (*destroy)(apriltag_family_t*) = nullptr;
    void operator()(apriltag_family_t* f) const {
        if (f) destroy(f);
    }
};
using FamilyPtr = std::unique_ptr<apriltag_family_t, FamilyDeleter>;

// Families with a square black border that tags are drawn from (the detector supports more; the
// board renderer needs only these).
FamilyPtr createFamily(const std::string& name) {
    struct Entry {
        const char* name;
        apriltag_family_t* (*create)();
        void (*destroy)(apriltag_family_t*);
    };
    static const Entry kEntries[] = {
        {"tag36h11", tag36h11_create, tag36h11_destroy},
        {"tag25h9", tag25h9_create, tag25h9_destroy},
        {"tag16h5", tag16h5_create, tag16h5_destroy},
        {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    };
    for (const Entry& e : kEntries)
        if (name == e.name) return FamilyPtr(e.create(), FamilyDeleter{e.destroy});
    return FamilyPtr(nullptr, FamilyDeleter{});
}

// apriltag_to_image's image comes from libapriltag's internal image_u8_create (two callocs);
// Debian exports image_u8_destroy only from libapriltag-utils, so free() both blocks here.
struct ImageU8Free {
    void operator()(image_u8_t* im) const {
        if (!im) return;
        std::free(im->buf);
        std::free(im);
    }
};

uint8_t texelByte(float albedo) {
    return uint8_t(std::lround(std::clamp(albedo, 0.0f, 1.0f) * 255.0f));
}

uint32_t greyTexel(uint8_t v) {
    return uint32_t(v) | uint32_t(v) << 8 | uint32_t(v) << 16 | 0xffu << 24;
}

glm::vec3 toGlm(const cv::Vec3d& v) { return glm::vec3(float(v[0]), float(v[1]), float(v[2])); }

cv::Vec3d column(const cv::Matx44d& m, int c) { return {m(0, c), m(1, c), m(2, c)}; }

// Two triangles spanning corners c[0..3] (counter-clockwise seen from the side `normal` points
// to, so that side is the front face that emits).
void addQuad(Scene& scene, const std::array<glm::vec3, 4>& c, const std::array<glm::vec2, 4>& uv,
             glm::vec3 normal, uint32_t material) {
    Geometry& g = scene.geometry;
    uint32_t base = uint32_t(g.positions.size());
    for (int i = 0; i < 4; ++i) {
        g.positions.push_back(c[i]);
        g.normals.push_back(normal);
        g.uvs.push_back(uv[i]);
    }
    glm::vec3 n = glm::cross(c[1] - c[0], c[2] - c[0]);
    bool ccw = glm::dot(n, normal) > 0.0f;
    glm::uvec3 t0 = ccw ? glm::uvec3(0, 1, 2) : glm::uvec3(0, 2, 1);
    glm::uvec3 t1 = ccw ? glm::uvec3(0, 2, 3) : glm::uvec3(0, 3, 2);
    for (glm::uvec3 t : {t0, t1}) {
        g.triangles.push_back(t + glm::uvec3(base));
        g.triangleMaterials.push_back(material);
        g.triangleIsReal.push_back(0);
    }
}

Material emissiveMaterial(const std::string& name, float emission, int texture) {
    // Black and not specular: the surface reflects nothing, it only emits (see BoardAppearance).
    Material m;
    m.name = name;
    m.baseColor = glm::vec4(0.0f, 0.0f, 0.0f, 1.0f);
    m.metallic = 0.0f;
    m.specular = 0.0f;
    m.emission = glm::vec3(emission);
    m.emissiveTexture = texture;
    return m;
}

}  // namespace

Result<TagBoard> gridBoard(int columns, int rows, double tagSizeM, double pitchM,
                           const std::string& family, int firstId) {
    if (columns < 1 || rows < 1 || !(tagSizeM > 0.0) || !(pitchM >= tagSizeM))
        return makeError(
            "tag grid {}x{}, tag {} m, pitch {} m: needs at least one tag and a pitch "
            "no smaller than the tag",
            columns, rows, tagSizeM, pitchM);
    // Tag frame (docs/board-format.md): x right, y down the print, z into it. Readable from +Z
    // with +Y up the print: x = world +X, y = world −Y, z = world −Z.
    const cv::Matx33d worldFromTagRotation = rotationFromEulerDeg(180.0, 0.0, 0.0);
    std::vector<BoardTag> tags;
    for (int r = 0; r < rows; ++r) {
        for (int c = 0; c < columns; ++c) {
            BoardTag tag;
            tag.id = firstId + r * columns + c;
            tag.sizeM = tagSizeM;
            tag.worldFromTag = cv::Matx44d::eye();
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) tag.worldFromTag(i, j) = worldFromTagRotation(i, j);
            tag.worldFromTag(0, 3) = (c - 0.5 * (columns - 1)) * pitchM;
            tag.worldFromTag(1, 3) = (0.5 * (rows - 1) - r) * pitchM;
            tags.push_back(tag);
        }
    }
    return TagBoard::create(std::move(tags), "generated tag grid", family);
}

TagBoard posterBoard() {
    auto board = gridBoard(4, 3, 0.10, 0.14);
    PV_ASSERT(board.ok());  // constant, valid arguments
    return std::move(board).value();
}

TagBoard vispRbtBoard() {
    std::vector<BoardTag> tags;
    for (int id = 0; id < 12; ++id) {
        BoardTag t{id, 0.0955};
        t.worldFromTag = cv::Matx44d(0, 1, 0, 0.05 + 0.12 * (id / 4), 1, 0, 0,
                                     0.045 + 0.12 * (id % 4), 0, 0, -1, 0, 0, 0, 0, 1);
        tags.push_back(t);
    }
    auto board = TagBoard::create(tags, "ViSP RBT board");
    PV_ASSERT(board.ok());  // constant, valid layout
    return std::move(board).value();
}

Result<Scene> tagBoardScene(const TagBoard& board, const std::string& family,
                            const BoardAppearance& appearance) {
    FamilyPtr fam = createFamily(family);
    if (!fam)
        return makeError(
            "cannot draw tag family '{}': use tag36h11, tag25h9, tag16h5 or "
            "tagStandard41h12",
            family);
    if (board.tags().empty()) return makeError("the board has no tags");
    if (appearance.texelsPerBit < 1 || appearance.texelsPerBit > 64)
        return makeError("texels per bit {}: must be 1..64", appearance.texelsPerBit);

    // The plane: the first tag's frame; every tag must share its z axis and its z = 0.
    const cv::Matx44d planeFromWorld = [&] {
        cv::Matx44d m = board.tags().front().worldFromTag;
        cv::Matx33d r = m.get_minor<3, 3>(0, 0).t();
        cv::Vec3d t = -(r * column(m, 3));
        cv::Matx44d out = cv::Matx44d::eye();
        for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) out(i, j) = r(i, j);
            out(i, 3) = t[i];
        }
        return out;
    }();
    const cv::Vec3d planeNormal = column(board.tags().front().worldFromTag, 2);  // into the tags

    Scene scene;
    scene.path = "rendered tag board";
    const uint8_t paper = texelByte(appearance.paperAlbedo);
    const uint8_t ink = texelByte(appearance.inkAlbedo);
    double lo[2] = {1e300, 1e300};
    double hi[2] = {-1e300, -1e300};
    const int bitsWide = fam->total_width;
    for (const BoardTag& tag : board.tags()) {
        if (tag.id < 0 || uint32_t(tag.id) >= fam->ncodes)
            return makeError("tag id {} is not in family {} (0..{})", tag.id, family,
                             fam->ncodes - 1);
        cv::Vec3d z = column(tag.worldFromTag, 2);
        cv::Vec3d offset =
            column(tag.worldFromTag, 3) - column(board.tags().front().worldFromTag, 3);
        if (z.dot(planeNormal) < 1.0 - 1e-9 || std::abs(offset.dot(planeNormal)) > 1e-6)
            return makeError(
                "tag {} is not on the plane of tag {}: the board renderer draws "
                "planar boards only",
                tag.id, board.tags().front().id);

        // The bitmap: total_width bits with the white border; the black square (the tag size)
        // is width_at_border bits.
        std::unique_ptr<image_u8_t, ImageU8Free> bits(apriltag_to_image(fam.get(), tag.id));
        if (!bits) return makeError("libapriltag could not draw tag {}", tag.id);
        const uint32_t n = appearance.texelsPerBit;
        Texture tex;
        tex.name = fmt::format("{} {}", family, tag.id);
        tex.width = tex.height = uint32_t(bitsWide) * n;
        tex.srgb = false;  // the bytes are albedo/255 directly
        tex.rgba8.resize(size_t(tex.width) * tex.height);
        for (uint32_t y = 0; y < tex.height; ++y)
            for (uint32_t x = 0; x < tex.width; ++x)
                tex.rgba8[size_t(y) * tex.width + x] =
                    greyTexel(bits->buf[(y / n) * bits->stride + x / n] ? paper : ink);
        scene.textures.push_back(std::move(tex));
        uint32_t material = uint32_t(scene.materials.size());
        scene.materials.push_back(
            emissiveMaterial(fmt::format("tag {}", tag.id), 1.0f, int(scene.textures.size() - 1)));

        // Row 0 of the bitmap is the top of the print (tag y = −half), glTF uv origin top left.
        const double half = 0.5 * tag.sizeM * bitsWide / fam->width_at_border;
        const double corners[4][2] = {{-half, -half}, {half, -half}, {half, half}, {-half, half}};
        std::array<glm::vec3, 4> world;
        std::array<glm::vec2, 4> uv;
        for (int i = 0; i < 4; ++i) {
            cv::Vec4d p = tag.worldFromTag * cv::Vec4d(corners[i][0], corners[i][1], 0.0, 1.0);
            world[i] = glm::vec3(float(p[0]), float(p[1]), float(p[2]));
            uv[i] = glm::vec2(float((corners[i][0] + half) / (2.0 * half)),
                              float((corners[i][1] + half) / (2.0 * half)));
            cv::Vec4d q = planeFromWorld * p;
            for (int a = 0; a < 2; ++a) {
                lo[a] = std::min(lo[a], q[a]);
                hi[a] = std::max(hi[a], q[a]);
            }
        }
        addQuad(scene, world, uv, -toGlm(z), material);
    }

    // The white paper around the tags, 1 mm behind them (tag +z) so the two never fight for a
    // pixel; both are white where they meet, so the step is invisible from any side.
    const double behindM = 1e-3;
    uint32_t backing = uint32_t(scene.materials.size());
    scene.materials.push_back(emissiveMaterial("paper", paper / 255.0f, -1));
    const cv::Matx44d worldFromPlane = board.tags().front().worldFromTag;
    const double m = appearance.marginM;
    const double plane[4][2] = {{lo[0] - m, lo[1] - m},
                                {hi[0] + m, lo[1] - m},
                                {hi[0] + m, hi[1] + m},
                                {lo[0] - m, hi[1] + m}};
    std::array<glm::vec3, 4> world;
    for (int i = 0; i < 4; ++i) {
        cv::Vec4d p = worldFromPlane * cv::Vec4d(plane[i][0], plane[i][1], behindM, 1.0);
        world[i] = glm::vec3(float(p[0]), float(p[1]), float(p[2]));
    }
    addQuad(scene, world, {glm::vec2(0.0f), glm::vec2(0.0f), glm::vec2(0.0f), glm::vec2(0.0f)},
            -toGlm(planeNormal), backing);

    Camera camera;
    camera.name = "tracked";
    scene.cameras.push_back(camera);
    return scene;
}

Result<BoardRenderer> BoardRenderer::create(GpuContext& ctx, const TagBoard& board,
                                            const std::string& family,
                                            const CameraCalibration& calibration, uint32_t spp,
                                            const BoardAppearance& appearance) {
    if (spp < 1) return makeError("board render: samples per pixel must be at least 1");
    auto scene = tagBoardScene(board, family, appearance);
    if (!scene) return scene.error();
    RenderSettings settings;
    settings.width = uint32_t(calibration.imageSize().width);
    settings.height = uint32_t(calibration.imageSize().height);
    // pbrt's maxdepth 0: only emission seen directly by camera rays, so the pixel is the
    // emitted radiance (the albedo) and no light sampling or bounce is traced for nothing.
    settings.maxDepth = 0;
    settings.samplesPerDispatch = spp;  // one dispatch per image
    settings.convergenceMeter = false;  // one sequence: nothing reads a noise estimate here
    auto grid = lensRayGrid(calibration, settings.width, settings.height);
    if (!grid) return grid.error();
    settings.lensGrid = std::move(grid).value();
    auto renderer = Renderer::create(ctx, *scene, settings);
    if (!renderer) return renderer.error();
    return BoardRenderer(std::move(renderer).value(), spp);
}

Result<ImageF> BoardRenderer::render(const cv::Matx44d& worldFromCameraCv, uint32_t seed) {
    renderer_->setCameraPose(renderWorldFromOpenCvCamera(worldFromCameraCv));
    renderer_->setSeed(seed);
    if (Status s = renderer_->reset(); !s) return s.error();
    if (Status s = renderer_->render(spp_); !s) return s.error();
    auto rgb = renderer_->image(Aov::Composite);
    if (!rgb) return rgb.error();
    ImageF grey;
    grey.width = rgb->width;
    grey.height = rgb->height;
    grey.channels = 1;
    grey.pixels.resize(size_t(grey.width) * grey.height);
    // The board is grey: all channels are equal, and their mean is the luminance.
    for (size_t i = 0; i < grey.pixels.size(); ++i) {
        const float* p = &rgb->pixels[i * rgb->channels];
        grey.pixels[i] = (p[0] + p[1] + p[2]) / 3.0f;
    }
    return grey;
}

cv::Mat toCameraGray8(const ImageF& linear, const Degradation& degradation) {
    PV_ASSERT(linear.channels == 1);
    // A view of the pixels (GaussianBlur writes to a new image, nothing writes through it).
    cv::Mat sharp(int(linear.height), int(linear.width), CV_32F,
                  const_cast<float*>(linear.pixels.data()));
    cv::Mat blurred;
    if (degradation.blurSigmaPx > 0.0)
        cv::GaussianBlur(sharp, blurred, cv::Size(0, 0), degradation.blurSigmaPx,
                         degradation.blurSigmaPx, cv::BORDER_REPLICATE);
    else
        blurred = sharp;
    cv::RNG rng(degradation.seed);
    cv::Mat out(blurred.size(), CV_8U);
    for (int y = 0; y < out.rows; ++y) {
        for (int x = 0; x < out.cols; ++x) {
            const float radiance = std::max(blurred.at<float>(y, x), 0.0f);
            double code = 255.0 * (degradation.curve == TransferCurve::Srgb ? srgbEncode(radiance)
                                                                            : radiance);
            if (degradation.noiseSigmaLevels > 0.0)
                code += rng.gaussian(degradation.noiseSigmaLevels);
            out.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(code);
        }
    }
    return out;
}

cv::Matx44d cameraViewingBoard(const BoardView& view) {
    const double a = view.angleDeg * kPi / 180.0;
    const double az = view.azimuthDeg * kPi / 180.0;
    const cv::Vec3d eye = view.distanceM * cv::Vec3d(std::sin(a) * std::cos(az),
                                                     std::sin(a) * std::sin(az), std::cos(a));
    const cv::Vec3d forward = cv::normalize(-eye);
    // Up the print (+Y) is up in the image, unless the camera looks along it.
    cv::Vec3d up(0.0, 1.0, 0.0);
    if (std::abs(forward.dot(up)) > 0.999) up = cv::Vec3d(0.0, 0.0, 1.0);
    const cv::Vec3d right = cv::normalize(forward.cross(up));
    const cv::Vec3d down = forward.cross(right);
    cv::Matx33d worldFromLookAt;
    for (int i = 0; i < 3; ++i) {
        worldFromLookAt(i, 0) = right[i];
        worldFromLookAt(i, 1) = down[i];
        worldFromLookAt(i, 2) = forward[i];
    }
    // Roll about the optical axis (z), then turn about the camera's y so the board centre sits
    // offAxisDeg to the side.
    cv::Matx33d roll;
    cv::Rodrigues(cv::Vec3d(0.0, 0.0, view.rollDeg * kPi / 180.0), roll);
    cv::Matx33d turn;
    cv::Rodrigues(cv::Vec3d(0.0, view.offAxisDeg * kPi / 180.0, 0.0), turn);
    const cv::Matx33d r = worldFromLookAt * roll * turn;
    cv::Matx44d out = cv::Matx44d::eye();
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) out(i, j) = r(i, j);
        out(i, 3) = eye[i];
    }
    return out;
}

CameraPoseError cameraPoseError(const cv::Matx44d& estimatedWorldFromCamera,
                                const cv::Matx44d& trueWorldFromCamera) {
    CameraPoseError e;
    e.translationM = cv::norm(column(estimatedWorldFromCamera, 3) - column(trueWorldFromCamera, 3));
    const cv::Matx33d rEst = estimatedWorldFromCamera.get_minor<3, 3>(0, 0);
    const cv::Matx33d rTrue = trueWorldFromCamera.get_minor<3, 3>(0, 0);
    // Rodrigues, not acos((trace − 1)/2): accurate for the tiny angles that matter here.
    cv::Vec3d axisAngle;
    cv::Rodrigues(rEst.t() * rTrue, axisAngle);
    e.rotationDeg = cv::norm(axisAngle) * 180.0 / kPi;
    return e;
}

}  // namespace previs
