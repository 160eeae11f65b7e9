// make_demo_session: generates examples/demo/ — the phantom set (scene.gltf, board.png), the
// recorded session the README's demo replays (docs/session-format.md v3) and, outside the take,
// a truth folder for tests (truth/: linear renders of the mixed and real-only scenes and the
// virtual mask at a few frames) — with previs's own path tracer, deterministically (fixed
// seeds). scripts/make_demo_session.sh runs it.
//
// The set: a table with an A3 tag board (examples/demo/board.toml) lying on it, a cardboard box,
// a floor, lit by an HDR environment map; virtual objects (a glossy red ball, a chrome ball) that
// the service composites. The scene camera (scene_camera.yaml) moves around the table, stays
// still while the mode button goes into refinement and back, and moves again; its frames show
// the real set only (the plate), tone mapped by the curve previsd.toml's radiometry inverts.
// The fisheye (fisheye.yaml, looking up) sees the environment map; the map turns a few degrees
// while the camera moves, so live lighting is visible. The fisheye brackets (DESIGN.md §4: an
// 8-bit camera clips every lamp): at each lighting instant one frame per exposure of
// --bracket-stops, through the same 8-bit curve as the plates.

#include <Imath/half.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfCompression.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <glm/gtc/quaternion.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/log.h"
#include "config/service_config.h"
#include "gpu/context.h"
#include "image/image.h"
#include "io/session.h"
#include "render/renderer.h"
#include "render/tonemap.h"
#include "scene/environment_map.h"
#include "scene/environment_sampler.h"
#include "scene/gltf_loader.h"
#include "take/take_files.h"
#include "vision/board_file.h"
#include "vision/camera_calibration.h"
#include "vision/lens_grid.h"
#include "vision/tag_board.h"

namespace previs {
namespace {

constexpr double kPi = 3.14159265358979323846;

// The session's timeline (DESIGN.md §5 demo): 15 fps, moving, still (refinement), moving.
constexpr int kFrames = 60;
constexpr int kStillFirst = 20;  // frames [kStillFirst, kStillLast] show the same view
constexpr int kStillLast = 44;
constexpr int kFisheyeEvery = 4;
constexpr uint64_t kStartNs = 1'000'000'000'000ULL;  // an arbitrary CLOCK_MONOTONIC origin
constexpr uint64_t kFrameNs = 66'666'667ULL;
// The fisheye runs at 30 fps while it brackets: a bracket's frames are 1/30 s apart, starting
// 1 ms after the scene frame of its instant (the two cameras are not synchronised).
constexpr uint64_t kBracketFrameNs = 33'333'333ULL;
constexpr uint64_t kFisheyeOffsetNs = 1'000'000ULL;

// The A3 sheet the tags are printed on, centred on the world origin (board.toml), and its texture
// resolution: 0.5 mm texels put every bit edge of 80 mm tags (10 mm bits) on a texel edge.
constexpr double kPaperWidthM = 0.42;
constexpr double kPaperHeightM = 0.297;
constexpr double kTexelM = 0.0005;
constexpr float kPaperAlbedo = 0.8f;
constexpr float kInkAlbedo = 0.04f;

// The camera frames' encoding: render/tonemap.h's reinhard-extended with L_max = L_white = 16,
// which previsd.toml's "banterle" radiometry inverts exactly; plus sensor noise on the codes.
constexpr float kMaxRadiance = 16.0f;
constexpr double kNoiseSigmaLevels = 1.5;

// The virtual balls (world metres): scene.gltf's spheres and the truth's regions.
struct VirtualBall {
    const char* name;  // in truth.toml
    const char* node;  // in scene.gltf
    double x, y, z, radiusM;
};
constexpr VirtualBall kRedBall{"red_ball", "RedBall", -0.33, 0.054, 0.06, 0.055};
constexpr VirtualBall kChromeBall{"chrome_ball", "ChromeBall", 0.06, 0.044, 0.23, 0.045};

struct Options {
    std::string demoDir;
    std::string envPath;
    float envScale = 0.6f;
    uint32_t movingSpp = 24;
    uint32_t stillSpp = 256;
    uint32_t maxDepth = 3;
    int frames = kFrames;  // fewer for a quick look
    // The fisheye's exposures at each lighting instant, in stops relative to its radiometry
    // (FrameStamp::exposureStops), in capture order.
    // At 0.6, studio_small_03's brightest channel is 2141 (7.1 stops over L_max = 16): −8 still
    // clips 34 coloured texels (the curve scales colour by a luminance ratio), −9 clips none
    // (code 241 before noise and JPEG), −10 leaves 35 codes of margin (220).
    std::vector<float> bracketStops{0.0f, -5.0f, -10.0f};
    // The truth folder: scene frames rendered as linear mixed/real/mask, with this many samples
    // per pixel (two independent halves; 0 writes no truth folder).
    std::vector<int> truthFrames{10, 32};
    uint32_t truthSpp = 1024;
    // The environment map's name relative to the shared data folder, for truth.toml (default:
    // its path from the "envmaps" folder on).
    std::string envName;
};

// --- the phantom set as glTF ------------------------------------------------------------------

struct GltfBuilder {
    nlohmann::json doc;
    std::vector<uint8_t> bin;

    GltfBuilder() {
        doc["asset"] = {{"version", "2.0"}, {"generator", "previs make_demo_session"}};
        for (const char* k : {"buffers", "bufferViews", "accessors", "meshes", "nodes", "materials",
                              "images", "textures", "samplers", "cameras"})
            doc[k] = nlohmann::json::array();
    }

    template <typename T>
    int addAccessor(const std::vector<T>& data, int components, int componentType, const char* type,
                    int target, bool minMax = false) {
        while (bin.size() % 4) bin.push_back(0);
        const size_t offset = bin.size();
        const auto* p = reinterpret_cast<const uint8_t*>(data.data());
        bin.insert(bin.end(), p, p + data.size() * sizeof(T));
        doc["bufferViews"].push_back({{"buffer", 0},
                                      {"byteOffset", offset},
                                      {"byteLength", data.size() * sizeof(T)},
                                      {"target", target}});
        nlohmann::json acc = {{"bufferView", doc["bufferViews"].size() - 1},
                              {"componentType", componentType},
                              {"count", data.size() / size_t(components)},
                              {"type", type}};
        if (minMax) {
            std::vector<float> lo(size_t(components), 1e30f), hi(size_t(components), -1e30f);
            for (size_t i = 0; i < data.size(); ++i) {
                lo[i % size_t(components)] = std::min(lo[i % size_t(components)], float(data[i]));
                hi[i % size_t(components)] = std::max(hi[i % size_t(components)], float(data[i]));
            }
            acc["min"] = lo;
            acc["max"] = hi;
        }
        doc["accessors"].push_back(acc);
        return int(doc["accessors"].size() - 1);
    }

    struct Mesh {
        std::vector<float> positions, normals, uvs;
        std::vector<uint32_t> indices;
        void vertex(glm::vec3 p, glm::vec3 n, glm::vec2 uv) {
            positions.insert(positions.end(), {p.x, p.y, p.z});
            normals.insert(normals.end(), {n.x, n.y, n.z});
            uvs.insert(uvs.end(), {uv.x, uv.y});
        }
        // Corners counter-clockwise seen from the side the normal points to.
        void quad(glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) {
            const glm::vec3 n = glm::normalize(glm::cross(b - a, c - a));
            const uint32_t base = uint32_t(positions.size() / 3);
            vertex(a, n, {0, 1});
            vertex(b, n, {1, 1});
            vertex(c, n, {1, 0});
            vertex(d, n, {0, 0});
            indices.insert(indices.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
        }
    };

    static Mesh box(glm::vec3 lo, glm::vec3 hi) {
        Mesh m;
        const glm::vec3 p[8] = {{lo.x, lo.y, lo.z}, {hi.x, lo.y, lo.z}, {hi.x, hi.y, lo.z},
                                {lo.x, hi.y, lo.z}, {lo.x, lo.y, hi.z}, {hi.x, lo.y, hi.z},
                                {hi.x, hi.y, hi.z}, {lo.x, hi.y, hi.z}};
        m.quad(p[4], p[5], p[6], p[7]);  // +z
        m.quad(p[1], p[0], p[3], p[2]);  // -z
        m.quad(p[5], p[1], p[2], p[6]);  // +x
        m.quad(p[0], p[4], p[7], p[3]);  // -x
        m.quad(p[7], p[6], p[2], p[3]);  // +y
        m.quad(p[0], p[1], p[5], p[4]);  // -y
        return m;
    }

    static Mesh sphere(glm::vec3 c, float r, int rings = 32, int segments = 64) {
        Mesh m;
        for (int i = 0; i <= rings; ++i) {
            const double theta = kPi * i / rings;
            for (int j = 0; j <= segments; ++j) {
                const double phi = 2.0 * kPi * j / segments;
                const glm::vec3 n(float(std::sin(theta) * std::cos(phi)), float(std::cos(theta)),
                                  float(-std::sin(theta) * std::sin(phi)));
                m.vertex(c + r * n, n, {float(j) / segments, float(i) / rings});
            }
        }
        for (int i = 0; i < rings; ++i)
            for (int j = 0; j < segments; ++j) {
                const uint32_t a = uint32_t(i * (segments + 1) + j), b = a + uint32_t(segments + 1);
                // At the poles one triangle of each quad has no area.
                if (i > 0) m.indices.insert(m.indices.end(), {a, b, a + 1});
                if (i < rings - 1) m.indices.insert(m.indices.end(), {a + 1, b, b + 1});
            }
        return m;
    }

    int addMaterial(const std::string& name, glm::vec3 color, float metallic, float roughness,
                    int texture = -1) {
        nlohmann::json pbr = {{"baseColorFactor", {color.r, color.g, color.b, 1.0}},
                              {"metallicFactor", metallic},
                              {"roughnessFactor", roughness}};
        if (texture >= 0) pbr["baseColorTexture"] = {{"index", texture}};
        doc["materials"].push_back({{"name", name}, {"pbrMetallicRoughness", pbr}});
        return int(doc["materials"].size() - 1);
    }

    void addNode(const std::string& name, const Mesh& m, int material, bool real) {
        constexpr int kFloat = 5126, kUint = 5125, kArray = 34962, kElements = 34963;
        nlohmann::json prim = {
            {"attributes",
             {{"POSITION", addAccessor(m.positions, 3, kFloat, "VEC3", kArray, true)},
              {"NORMAL", addAccessor(m.normals, 3, kFloat, "VEC3", kArray)},
              {"TEXCOORD_0", addAccessor(m.uvs, 2, kFloat, "VEC2", kArray)}}},
            {"indices", addAccessor(m.indices, 1, kUint, "SCALAR", kElements)},
            {"material", material}};
        doc["meshes"].push_back({{"name", name}, {"primitives", {prim}}});
        nlohmann::json node = {{"name", name}, {"mesh", doc["meshes"].size() - 1}};
        // DESIGN.md §4: a phantom of a real object.
        if (real) node["extras"] = {{"previs", {{"role", "real"}}}};
        doc["nodes"].push_back(node);
    }
};

// The board print: sRGB-encoded albedo, row 0 at the sheet's top edge (world −Z).
Result<std::vector<uint8_t>> boardTexture(const TagBoard& board, uint32_t& width,
                                          uint32_t& height) {
    width = uint32_t(std::lround(kPaperWidthM / kTexelM));
    height = uint32_t(std::lround(kPaperHeightM / kTexelM));
    const uint8_t paper = uint8_t(std::lround(255.0f * srgbEncode(kPaperAlbedo)));
    const uint8_t ink = uint8_t(std::lround(255.0f * srgbEncode(kInkAlbedo)));
    std::vector<uint8_t> rgb(size_t(width) * height * 3, paper);
    std::unique_ptr<apriltag_family_t, void (*)(apriltag_family_t*)> fam(tag36h11_create(),
                                                                         tag36h11_destroy);
    if (board.family() != "tag36h11")
        return makeError("make_demo_session draws tag36h11 boards only, not {}", board.family());
    for (const BoardTag& tag : board.tags()) {
        // Flat on the table, readable from above: tag x = world +X, tag y = world +Z.
        if (std::abs(tag.worldFromTag(1, 3)) > 1e-9 ||
            std::abs(tag.worldFromTag(1, 2) + 1.0) > 1e-9)
            return makeError("board tag {} does not lie flat at y = 0", tag.id);
        image_u8_t* bits = apriltag_to_image(fam.get(), tag.id);
        if (!bits) return makeError("libapriltag could not draw tag {}", tag.id);
        const double bitM = tag.sizeM / fam->width_at_border;
        const double halfM = 0.5 * bitM * fam->total_width;
        const double x0 = tag.worldFromTag(0, 3) - halfM + 0.5 * kPaperWidthM;
        const double y0 = tag.worldFromTag(2, 3) - halfM + 0.5 * kPaperHeightM;
        for (uint32_t y = 0; y < height; ++y)
            for (uint32_t x = 0; x < width; ++x) {
                const double bx = ((x + 0.5) * kTexelM - x0) / bitM;
                const double by = ((y + 0.5) * kTexelM - y0) / bitM;
                if (bx < 0 || by < 0 || bx >= fam->total_width || by >= fam->total_width) continue;
                const uint8_t v = bits->buf[int(by) * bits->stride + int(bx)] ? paper : ink;
                for (int c = 0; c < 3; ++c) rgb[(size_t(y) * width + x) * 3 + c] = v;
            }
        // apriltag_to_image allocates with calloc (render/board_render.cpp: no exported destroy).
        std::free(bits->buf);
        std::free(bits);
    }
    return rgb;
}

Status writeSceneGltf(const Options& o, const TagBoard& board, const cv::Matx44d& cameraPose,
                      const CameraCalibration& calibration) {
    uint32_t tw = 0, th = 0;
    auto texture = boardTexture(board, tw, th);
    if (!texture) return texture.error();
    if (Status s = writePng(o.demoDir + "/board.png", tw, th, *texture); !s) return s;

    GltfBuilder g;
    g.doc["images"].push_back({{"uri", "board.png"}});
    g.doc["samplers"].push_back({{"magFilter", 9729}, {"minFilter", 9729}});
    g.doc["textures"].push_back({{"source", 0}, {"sampler", 0}});
    const int boardMat = g.addMaterial("BoardPrint", glm::vec3(1.0f), 0.0f, 0.9f, 0);
    const int wood = g.addMaterial("TableWood", {0.42f, 0.27f, 0.15f}, 0.0f, 0.7f);
    const int floor = g.addMaterial("Floor", {0.25f, 0.25f, 0.27f}, 0.0f, 0.9f);
    const int cardboard = g.addMaterial("Cardboard", {0.55f, 0.38f, 0.22f}, 0.0f, 0.95f);
    const int red = g.addMaterial("RedPlastic", {0.7f, 0.04f, 0.03f}, 0.0f, 0.15f);
    const int chrome = g.addMaterial("Chrome", {0.95f, 0.95f, 0.95f}, 1.0f, 0.03f);

    const float hx = float(0.5 * kPaperWidthM), hz = float(0.5 * kPaperHeightM);
    GltfBuilder::Mesh paper;
    paper.quad({-hx, 0, hz}, {hx, 0, hz}, {hx, 0, -hz}, {-hx, 0, -hz});
    g.addNode("Board", paper, boardMat, true);
    // The table top 1 mm under the print, so the two never fight for a pixel.
    g.addNode("Table", GltfBuilder::box({-0.6f, -0.75f, -0.4f}, {0.6f, -0.001f, 0.4f}), wood, true);
    GltfBuilder::Mesh floorMesh;
    floorMesh.quad({-4, -0.75f, 4}, {4, -0.75f, 4}, {4, -0.75f, -4}, {-4, -0.75f, -4});
    g.addNode("Floor", floorMesh, floor, true);
    g.addNode("Box", GltfBuilder::box({0.26f, -0.001f, -0.2f}, {0.44f, 0.139f, -0.06f}), cardboard,
              true);
    for (auto [ball, material] : {std::pair{kRedBall, red}, {kChromeBall, chrome}})
        g.addNode(
            ball.node,
            GltfBuilder::sphere({float(ball.x), float(ball.y), float(ball.z)}, float(ball.radiusM)),
            material, false);

    // The camera at the still view, so `previs render examples/demo/previs.toml` shows the shot.
    const glm::mat4 m = renderWorldFromOpenCvCamera(cameraPose);
    const glm::quat q = glm::quat_cast(glm::mat3(m));
    const double fovY = 2.0 * std::atan(0.5 * calibration.imageSize().height / calibration.fy());
    g.doc["cameras"].push_back(
        {{"type", "perspective"},
         {"perspective",
          {{"yfov", fovY},
           {"aspectRatio", double(calibration.imageSize().width) / calibration.imageSize().height},
           {"znear", 0.01}}}});
    g.doc["nodes"].push_back({{"name", "SceneCamera"},
                              {"camera", 0},
                              {"translation", {m[3][0], m[3][1], m[3][2]}},
                              {"rotation", {q.x, q.y, q.z, q.w}}});
    nlohmann::json nodes = nlohmann::json::array();
    for (size_t i = 0; i < g.doc["nodes"].size(); ++i) nodes.push_back(i);
    g.doc["scenes"] = {{{"nodes", nodes}}};
    g.doc["scene"] = 0;
    g.doc["buffers"].push_back({{"uri", "scene.bin"}, {"byteLength", g.bin.size()}});

    std::ofstream bin(o.demoDir + "/scene.bin", std::ios::binary);
    bin.write(reinterpret_cast<const char*>(g.bin.data()), std::streamsize(g.bin.size()));
    std::ofstream gltf(o.demoDir + "/scene.gltf");
    gltf << g.doc.dump(1) << "\n";
    if (!bin || !gltf) return makeError("{}: cannot write scene.gltf/scene.bin", o.demoDir);
    return {};
}

// --- the camera path ----------------------------------------------------------------------------

cv::Matx44d lookAt(const cv::Vec3d& eye, const cv::Vec3d& target) {
    // OpenCV camera axes (x right, y down, z forward), world +Y up.
    const cv::Vec3d forward = cv::normalize(target - eye);
    const cv::Vec3d right = cv::normalize(forward.cross(cv::Vec3d(0, 1, 0)));
    const cv::Vec3d down = forward.cross(right);
    cv::Matx44d m = cv::Matx44d::eye();
    for (int i = 0; i < 3; ++i) {
        m(i, 0) = right[i];
        m(i, 1) = down[i];
        m(i, 2) = forward[i];
        m(i, 3) = eye[i];
    }
    return m;
}

double smooth(double t) { return t * t * (3.0 - 2.0 * t); }

// worldFromCamera of frame i: an arc around the table's front, a still stretch, another arc.
cv::Matx44d cameraPose(int i) {
    struct Key {
        double azimuthDeg, radiusM, heightM;
    };
    const Key a{-35.0, 0.62, 0.56}, b{0.0, 0.55, 0.50}, c{30.0, 0.60, 0.42};
    Key k;
    auto mix = [](const Key& p, const Key& q, double t) {
        return Key{p.azimuthDeg + (q.azimuthDeg - p.azimuthDeg) * t,
                   p.radiusM + (q.radiusM - p.radiusM) * t,
                   p.heightM + (q.heightM - p.heightM) * t};
    };
    if (i < kStillFirst)
        k = mix(a, b, smooth(double(i) / kStillFirst));
    else if (i <= kStillLast)
        k = b;
    else
        k = mix(b, c, smooth(double(i - kStillLast) / (kFrames - 1 - kStillLast)));
    const double az = k.azimuthDeg * kPi / 180.0;
    return lookAt({k.radiusM * std::sin(az), k.heightM, k.radiusM * std::cos(az)},
                  {0.0, 0.03, 0.0});
}

// The environment turns while the camera moves and holds still while it does (refinement needs
// a frozen scene).
double envRotationDeg(int i) {
    if (i < kStillFirst) return 10.0 * i / kStillFirst;
    if (i <= kStillLast) return 10.0;
    return 10.0 + 10.0 * (i - kStillLast) / (kFrames - 1 - kStillLast);
}

// --- encoding -------------------------------------------------------------------------------

// The camera's tone curve, which previsd.toml's radiometry inverts, at an exposure of `stops`
// (the linear image × 2^stops before the curve, as a bracketed frame receives it).
ToneMapSettings cameraCurve(float stops) {
    ToneMapSettings tm;
    tm.op = ToneMapOperator::ReinhardExtended;
    tm.maxRadiance = kMaxRadiance;
    tm.whiteLuminance = kMaxRadiance;
    tm.exposureStops = stops;
    return tm;
}

// Linear radiance → the camera's 8-bit frame: the tone curve the config inverts at an exposure
// of `stops`, then sensor noise on the code values.
std::vector<uint8_t> encodeFrame(const ImageF& linear, uint64_t seed, int& width, int& height,
                                 float stops = 0.0f) {
    const ToneMapSettings tm = cameraCurve(stops);
    cv::RNG rng(seed);
    width = int(linear.width);
    height = int(linear.height);
    cv::Mat bgr(height, width, CV_8UC3);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const float* p = &linear.pixels[(size_t(y) * width + x) * linear.channels];
            const std::array<float, 3> enc = toneMapRgb({p[0], p[1], p[2]}, tm);
            cv::Vec3b& out = bgr.at<cv::Vec3b>(y, x);
            for (int c = 0; c < 3; ++c)
                out[2 - c] =
                    cv::saturate_cast<uint8_t>(255.0 * enc[c] + rng.gaussian(kNoiseSigmaLevels));
        }
    std::vector<uint8_t> jpeg;
    cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 92});
    return jpeg;
}

// What the up-looking equidistant fisheye sees of the distant environment (k = 0: the angle off
// the axis is r / f), through the mount rotation of previsd.toml.
Result<ImageF> fisheyeImage(const CameraCalibration& cal, const EnvironmentSampler& env,
                            float scale) {
    for (double k : cal.distortion())
        if (k != 0.0) return makeError("fisheye.yaml: the generator draws k = 0 lenses only");
    const cv::Matx33d worldFromFisheye = rotationFromEulerDeg(-90.0, 0.0, 0.0);
    const double maxAngle = 95.0 * kPi / 180.0;
    ImageF img;
    img.width = uint32_t(cal.imageSize().width);
    img.height = uint32_t(cal.imageSize().height);
    img.channels = 3;
    img.pixels.assign(size_t(img.width) * img.height * 3, 0.0f);
    constexpr int kSub = 3;  // supersampling: the box pixel filter
    for (uint32_t y = 0; y < img.height; ++y)
        for (uint32_t x = 0; x < img.width; ++x) {
            glm::vec3 sum(0.0f);
            for (int sy = 0; sy < kSub; ++sy)
                for (int sx = 0; sx < kSub; ++sx) {
                    // OpenCV pixel centres are integers: pixel x covers [x − 0.5, x + 0.5).
                    const double u = (x - 0.5 + (sx + 0.5) / kSub - cal.cx()) / cal.fx();
                    const double v = (y - 0.5 + (sy + 0.5) / kSub - cal.cy()) / cal.fy();
                    const double theta = std::hypot(u, v);
                    if (theta > maxAngle) continue;
                    const double s = theta > 1e-12 ? std::sin(theta) / theta : 1.0;
                    const cv::Vec3d d = worldFromFisheye * cv::Vec3d(u * s, v * s, std::cos(theta));
                    sum += env.radiance(glm::vec3(float(d[0]), float(d[1]), float(d[2])));
                }
            for (int c = 0; c < 3; ++c)
                img.pixels[(size_t(y) * img.width + x) * 3 + c] = scale * sum[c] / (kSub * kSub);
        }
    return img;
}

// The environment's brightest texel (× scale) and whether each bracket exposure keeps every
// texel below display white: the curve acts on luminance and scales the colour, so a channel
// clips when its display value reaches 1 (code 255), before the luminance reaches L_white for
// a coloured lamp. Returns the shortest exposure's largest display value over the channels.
float checkBracketClipping(const EnvironmentMap& env, const std::vector<float>& stops) {
    glm::vec3 brightest(0.0f);
    float maxChannel = 0.0f;
    for (const glm::vec3& t : env.radiance) {
        const glm::vec3 l = env.scale * t;
        if (luminance(l) > luminance(brightest)) brightest = l;
        maxChannel = std::max({maxChannel, l.r, l.g, l.b});
    }
    logInfo(
        "environment {}: {}x{}, scale {}: brightest texel RGB ({:.1f}, {:.1f}, {:.1f}), "
        "luminance {:.1f}; largest channel {:.1f} ({:.2f} stops over L_max = {})",
        env.path, env.width, env.height, env.scale, brightest.r, brightest.g, brightest.b,
        luminance(brightest), maxChannel, std::log2(maxChannel / kMaxRadiance), kMaxRadiance);
    float shortestDisplay = 0.0f;
    const float shortest = stops.empty() ? 0.0f : *std::min_element(stops.begin(), stops.end());
    for (float s : stops) {
        float display = 0.0f;
        size_t clipped = 0;
        for (const glm::vec3& t : env.radiance) {
            const glm::vec3 l = env.scale * t;
            const std::array<float, 3> enc = toneMapRgb({l.r, l.g, l.b}, cameraCurve(s));
            const float m = std::max({enc[0], enc[1], enc[2]});
            display = std::max(display, m);
            clipped += m >= 1.0f;
        }
        logInfo("bracket {:+.1f} stops: {} texels clipped, brightest code {:.1f} of 255", s,
                clipped, 255.0f * display);
        if (s == shortest) shortestDisplay = display;
    }
    // The longest whole-stop exposure that clips no channel of any texel.
    auto clips = [&](float s) {
        for (const glm::vec3& t : env.radiance) {
            const glm::vec3 l = env.scale * t;
            const std::array<float, 3> enc = toneMapRgb({l.r, l.g, l.b}, cameraCurve(s));
            if (std::max({enc[0], enc[1], enc[2]}) >= 1.0f) return true;
        }
        return false;
    };
    float needed = 0.0f;
    while (needed > -30.0f && clips(needed)) needed -= 1.0f;
    logInfo("the longest whole-stop exposure that clips no texel: {:+.0f} stops", needed);
    return shortestDisplay;
}

// A linear image as OpenEXR half float (11 significant bits: rounding within 0.05 %, ample for
// tests whose tolerances are ~1 %, at half the size of float), PIZ compressed (lossless; suits
// noisy renders). 1 channel is written as "Y", 3 as RGB.
Status writeHalfExr(const std::string& path, const ImageF& image) {
    static const char* const kRgb[] = {"R", "G", "B"};
    if (image.channels != 1 && image.channels != 3)
        return makeError("{}: {} channels (1 or 3 expected)", path, image.channels);
    std::vector<Imath::half> px(image.pixels.size());
    for (size_t i = 0; i < px.size(); ++i) px[i] = Imath::half(image.pixels[i]);
    try {
        Imf::Header header{int(image.width), int(image.height)};
        header.compression() = Imf::PIZ_COMPRESSION;
        Imf::FrameBuffer fb;
        const size_t xStride = sizeof(Imath::half) * image.channels;
        for (uint32_t c = 0; c < image.channels; ++c) {
            const char* name = image.channels == 1 ? "Y" : kRgb[c];
            header.channels().insert(name, Imf::Channel(Imf::HALF));
            fb.insert(name, Imf::Slice(Imf::HALF, reinterpret_cast<char*>(px.data() + c), xStride,
                                       xStride * image.width));
        }
        Imf::OutputFile file(path.c_str(), header);
        file.setFrameBuffer(fb);
        file.writePixels(int(image.height));
    } catch (const std::exception& e) {
        return makeError("{}: cannot write OpenEXR: {}", path, e.what());
    }
    return {};
}

// --- the truth folder -------------------------------------------------------------------------

// Two independent renders (halves) of one AOV and their mean.
struct TruthAov {
    ImageF a, b, mean;
};

struct RegionStat {
    std::string name;
    size_t pixels = 0;
    double value = 0.0;   // of the mean image (a mean radiance, or a sum for the shadow)
    double halves = 0.0;  // |value(a) − value(b)| / 2: one draw of the mean's error
    double stdErr = 0.0;  // from the per-pixel differences of the halves (pixels independent)
};

// Mean luminance of `img` (or of real − mixed for a sum) over a pixel set.
RegionStat regionStat(const std::string& name, const std::vector<size_t>& px,
                      const std::function<double(const ImageF&, const ImageF&, size_t)>& f,
                      const TruthAov& x, const TruthAov& y, bool sum) {
    RegionStat r;
    r.name = name;
    r.pixels = px.size();
    if (px.empty()) return r;
    double va = 0.0, vb = 0.0, sq = 0.0;
    for (size_t p : px) {
        const double a = f(x.a, y.a, p), b = f(x.b, y.b, p);
        va += a;
        vb += b;
        sq += (a - b) * (a - b);
    }
    // The mean's pixel p is (a_p + b_p)/2, of variance (a_p − b_p)²/4 on average.
    const double n = sum ? 1.0 : double(px.size());
    r.value = 0.5 * (va + vb) / n;
    r.halves = 0.5 * std::abs(va - vb) / n;
    r.stdErr = 0.5 * std::sqrt(sq) / n;
    return r;
}

double lumAt(const ImageF& img, size_t p) {
    const float* v = &img.pixels[p * img.channels];
    return luminance(v[0], v[1], v[2]);
}

// A TOML float: `significant` digits (0: the shortest round trip of T), always with a point or
// an exponent, never −0.
template <typename T>
std::string tomlFloat(T v, int significant = 0) {
    v = v == T(0) ? T(0) : v;
    std::string t = significant ? fmt::format("{:.{}g}", v, significant) : fmt::format("{}", v);
    if (t.find_first_of(".en") == std::string::npos) t += ".0";
    return t;
}

// The environment map's name in the shared data folder: its path from "envmaps" on.
std::string envDataName(const std::string& path) {
    std::filesystem::path rel;
    bool found = false;
    for (const auto& part : std::filesystem::path(path)) {
        if (part == "envmaps") found = true;
        if (found) rel /= part;
    }
    return found ? rel.string() : std::filesystem::path(path).filename().string();
}

struct TruthContext {
    const Options& o;
    Scene& scene;  // the whole set, real and virtual
    GpuContext& ctx;
    RenderSettings settings;  // the plates' settings
    const CameraCalibration& cal;
    std::function<std::shared_ptr<EnvironmentMap>(int)> envAt;
};

// previsd.toml and every file it names, copied into the session as the take recorder copies
// them (take/take_files.h), and the session's config.toml naming the copies.
Status copyDemoConfig(const std::string& demoDir, const std::string& sessionDir) {
    Result<ServiceConfig> live = loadServiceConfig(demoDir + "/previsd.toml");
    if (!live) return live.error();
    Result<std::string> config = copyConfigIntoTake(*live, sessionDir);
    if (!config) return config.error();
    return writeFileAtomic(sessionDir + "/config.toml",
                           {reinterpret_cast<const uint8_t*>(config->data()), config->size()});
}

// Renders the truth frames and writes truth/ (truth.toml and the EXRs).
Status writeTruth(TruthContext& t) {
    const Options& o = t.o;
    const std::string dir = o.demoDir + "/truth";
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
    std::filesystem::create_directories(dir, ec);
    if (ec) return makeError("{}: cannot create: {}", dir, ec.message());
    RenderSettings settings = t.settings;
    settings.differential = true;  // L_or beside L_om, as the service renders it
    auto renderer = Renderer::create(t.ctx, t.scene, settings);
    if (!renderer) return renderer.error();
    Renderer& r = **renderer;
    const uint32_t half = std::max<uint32_t>(1, o.truthSpp / 2);

    const VirtualBall balls[] = {kRedBall, kChromeBall};  // to split the mask among them

    std::string toml = fmt::format(
        "# The demo's truth, for tests (bench/make_demo_session.cpp writes it with the session;\n"
        "# it is not part of the take). Renders with the plates' renderer and settings: linear\n"
        "# radiance, {}x{} (the plate's size and lens, scene_camera.yaml), max depth {}.\n"
        "#   mixed: L_om, the real set and the virtual objects; real: L_or, the real set only\n"
        "#   (what the plate encodes, before the camera curve and noise); mask: the fraction of\n"
        "#   each pixel's camera rays whose first hit is virtual.\n"
        "# OpenEXR half float, PIZ. Each image is the mean of two independent renders of {} spp\n"
        "# (seeds in seeds = [a, b]); [frame.regions] gives region values of the mean with their\n"
        "# error: halves = |value(a) - value(b)| / 2 (one draw), std_err = from the per-pixel\n"
        "# differences of the two halves. Luminance is Rec. 709. Regions: a ball, the pixels\n"
        "# with mask > 0.999 nearest its projected centre ({} centre ({}, {}, {}),\n"
        "# {} ({}, {}, {})), value = mean luminance of mixed there; the shadow,\n"
        "# the pixels with mask < 0.001 where luminance(real - mixed) > 5 % of luminance(real),\n"
        "# value = the sum of luminance(real - mixed) over them.\n"
        "version = 1\n"
        "spp = {}\n"
        "max_depth = {}\n"
        "width = {}\n"
        "height = {}\n"
        "camera = \"../scene_camera.yaml\"\n"
        "scene = \"../scene.gltf\"\n\n"
        "[environment]\n"
        "# relative to the shared data folder (PREVIS_DATA_DIR, ../shared/data beside the "
        "checkout)\n"
        "map = \"{}\"\n"
        "scale = {}\n"
        "# each frame's env_rotation_deg turns the map about world +Y as previs render's\n"
        "# --env-rotation does (DESIGN.md §4: positive = counter-clockwise seen from above)\n"
        "rotation = \"--env-rotation\"\n",
        settings.width, settings.height, settings.maxDepth, half, kRedBall.name, kRedBall.x,
        kRedBall.y, kRedBall.z, kChromeBall.name, kChromeBall.x, kChromeBall.y, kChromeBall.z,
        2 * half, settings.maxDepth, settings.width, settings.height,
        o.envName.empty() ? envDataName(o.envPath) : o.envName, tomlFloat(o.envScale));

    for (int f : o.truthFrames) {
        const cv::Matx44d pose = cameraPose(f);
        r.setCameraPose(renderWorldFromOpenCvCamera(pose));
        if (Status s = r.setEnvironment(t.envAt(f)); !s) return s;
        TruthAov mixed, real, mask;
        const uint32_t seeds[2] = {uint32_t(900000 + 2 * f), uint32_t(900000 + 2 * f + 1)};
        for (int h = 0; h < 2; ++h) {
            const auto start = std::chrono::steady_clock::now();
            r.setSeed(seeds[h]);
            if (Status s = r.reset(); !s) return s;
            if (Status s = r.render(half); !s) return s;
            auto m = r.image(Aov::Mixed);
            auto re = m ? r.image(Aov::Real) : Result<ImageF>(m.error());
            auto k = re ? r.image(Aov::Mask) : Result<ImageF>(re.error());
            if (!k) return k.error();
            (h ? mixed.b : mixed.a) = std::move(m).value();
            (h ? real.b : real.a) = std::move(re).value();
            (h ? mask.b : mask.a) = std::move(k).value();
            logInfo(
                "truth frame {}: half {} rendered {} spp in {:.1f} s", f, h, half,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        }
        for (TruthAov* x : {&mixed, &real, &mask}) {
            x->mean = x->a;
            for (size_t i = 0; i < x->mean.pixels.size(); ++i)
                x->mean.pixels[i] = 0.5f * (x->a.pixels[i] + x->b.pixels[i]);
        }

        // Regions: each ball's fully virtual pixels (the nearest projected centre), and the
        // shadow — real pixels where the virtual objects take away more than 5 % of L_or.
        const size_t n = size_t(settings.width) * settings.height;
        const cv::Matx44d cameraFromWorld = pose.inv();
        std::vector<cv::Point3d> centres;
        for (const VirtualBall& b : balls) {
            const cv::Vec4d c = cameraFromWorld * cv::Vec4d(b.x, b.y, b.z, 1);
            centres.emplace_back(c[0], c[1], c[2]);
        }
        const std::vector<cv::Point2d> centrePx = t.cal.projectPoints(centres);
        std::vector<std::vector<size_t>> ballPx(std::size(balls));
        std::vector<size_t> shadowPx;
        for (size_t p = 0; p < n; ++p) {
            const float m = mask.mean.pixels[p];
            const double x = double(p % settings.width), y = double(p / settings.width);
            if (m > 0.999f) {
                size_t best = 0;
                for (size_t b = 1; b < centrePx.size(); ++b)
                    if (std::hypot(x - centrePx[b].x, y - centrePx[b].y) <
                        std::hypot(x - centrePx[best].x, y - centrePx[best].y))
                        best = b;
                ballPx[best].push_back(p);
            } else if (m < 0.001f) {
                const double lr = lumAt(real.mean, p), lm = lumAt(mixed.mean, p);
                if (lr - lm > 0.05 * lr) shadowPx.push_back(p);
            }
        }
        std::vector<RegionStat> stats;
        for (size_t b = 0; b < std::size(balls); ++b)
            stats.push_back(regionStat(
                std::string(balls[b].name) + "_mean_luminance", ballPx[b],
                [](const ImageF& m, const ImageF&, size_t p) { return lumAt(m, p); }, mixed, mixed,
                false));
        stats.push_back(regionStat(
            "shadow_sum_luminance", shadowPx,
            [](const ImageF& re, const ImageF& m, size_t p) { return lumAt(re, p) - lumAt(m, p); },
            real, mixed, true));

        const std::string stem = fmt::format("frame_{:06d}", f);
        for (auto [aov, img] : {std::pair<const char*, const ImageF*>{"mixed", &mixed.mean},
                                {"real", &real.mean},
                                {"mask", &mask.mean}})
            if (Status s = writeHalfExr(fmt::format("{}/{}.{}.exr", dir, stem, aov), *img); !s)
                return s;
        std::string m16;
        for (int i = 0; i < 16; ++i)
            m16 += fmt::format("{}{}", i ? ", " : "", tomlFloat(pose(i / 4, i % 4)));
        toml += fmt::format(
            "\n[[frame]]\n"
            "index = {}  # the scene camera's frame in session/ (0-based)\n"
            "still = {}\n"
            "env_rotation_deg = {}\n"
            "# OpenCV camera axes (x right, y down, z forward), row-major, as session/poses.csv\n"
            "world_from_camera = [{}]\n"
            "seeds = [{}, {}]\n"
            "mixed = \"{}.mixed.exr\"\n"
            "real = \"{}.real.exr\"\n"
            "mask = \"{}.mask.exr\"\n",
            f, f >= kStillFirst && f <= kStillLast ? "true" : "false", tomlFloat(envRotationDeg(f)),
            m16, seeds[0], seeds[1], stem, stem, stem);
        toml += "[frame.regions]\n";
        for (const RegionStat& st : stats) {
            toml += fmt::format("{} = {{ pixels = {}, value = {}, halves = {}, std_err = {} }}\n",
                                st.name, st.pixels, tomlFloat(st.value, 7), tomlFloat(st.halves, 3),
                                tomlFloat(st.stdErr, 3));
            logInfo(
                "truth frame {}: {} over {} px = {:.5g}, error: halves {:.3f} %, std_err "
                "{:.3f} %",
                f, st.name, st.pixels, st.value, 100.0 * st.halves / std::abs(st.value),
                100.0 * st.stdErr / std::abs(st.value));
        }
    }
    std::ofstream out(dir + "/truth.toml");
    out << toml;
    if (!out) return makeError("{}/truth.toml: cannot write", dir);
    return {};
}

// --- main -------------------------------------------------------------------------------------

int run(const Options& o) {
    auto board = loadTagBoard(o.demoDir + "/board.toml");
    auto sceneCal = CameraCalibration::load(o.demoDir + "/scene_camera.yaml");
    auto fisheyeCal = CameraCalibration::load(o.demoDir + "/fisheye.yaml");
    for (const std::string* err :
         {board ? nullptr : &board.message(), sceneCal ? nullptr : &sceneCal.message(),
          fisheyeCal ? nullptr : &fisheyeCal.message()})
        if (err) {
            logError("{}", *err);
            return 2;
        }
    if (Status s = writeSceneGltf(o, *board, cameraPose(kStillFirst), *sceneCal); !s) {
        logError("{}", s.message());
        return 1;
    }
    auto scene = loadGltf(o.demoDir + "/scene.gltf");
    if (!scene) {
        logError("{}", scene.message());
        return 1;
    }
    // The plate shows the real set only: drop the virtual triangles.
    const Geometry& all = scene->geometry;
    Geometry real = realGeometry(all);
    logInfo("scene: {} triangles, {} real", all.triangles.size(), real.triangles.size());
    Geometry wholeSet = std::move(scene->geometry);  // for the truth renders
    scene->geometry = std::move(real);

    auto env = loadEnvironmentMap(o.envPath);
    if (!env) {
        logError("{}", env.message());
        return 2;
    }
    env->scale = o.envScale;
    if (checkBracketClipping(*env, o.bracketStops) >= 1.0f)
        logWarning(
            "the shortest bracket exposure clips the environment's brightest texels "
            "(--bracket-stops)");
    auto envAt = [&](int frame) {
        auto m = std::make_shared<EnvironmentMap>(*env);
        m->rotationRad = float(envRotationDeg(frame) * kPi / 180.0);
        return m;
    };
    scene->environment = *envAt(0);

    auto ctx = GpuContext::create({});
    if (!ctx) {
        logError("{}", ctx.message());
        return 1;
    }
    RenderSettings settings;
    settings.width = uint32_t(sceneCal->imageSize().width);
    settings.height = uint32_t(sceneCal->imageSize().height);
    settings.maxDepth = o.maxDepth;
    settings.samplesPerDispatch = 4;
    auto grid = lensRayGrid(*sceneCal, settings.width, settings.height);
    if (!grid) {
        logError("{}", grid.message());
        return 2;
    }
    settings.lensGrid = std::move(grid).value();
    auto renderer = Renderer::create(**ctx, *scene, settings);
    if (!renderer) {
        logError("{}", renderer.message());
        return 1;
    }

    const std::string sessionDir = o.demoDir + "/session";
    std::error_code ec;
    std::filesystem::remove_all(sessionDir, ec);
    // The session is a take like any other (docs/session-format.md, "A take is untrusted"): its
    // config.toml names copies inside it, written once its camera folders exist (below).
    SessionWriterOptions wo;
    wo.cameraRoles = {{"scene", "scene"}, {"fisheye", "fisheye"}};
    wo.created = "2025-01-01T12:00:00Z";  // fixed: regeneration is byte-identical
    auto writer = SessionWriter::create(sessionDir, wo);
    if (!writer) {
        logError("{}", writer.message());
        return 1;
    }

    std::optional<ImageF> still;
    uint32_t fisheyeSeq = 0;
    for (int i = 0; i < o.frames; ++i) {
        const uint64_t t = kStartNs + uint64_t(i) * kFrameNs;
        const cv::Matx44d pose = cameraPose(i);
        const bool isStill = i >= kStillFirst && i <= kStillLast;
        ImageF linear;
        if (isStill && still) {
            linear = *still;
        } else {
            auto start = std::chrono::steady_clock::now();
            (*renderer)->setCameraPose(renderWorldFromOpenCvCamera(pose));
            (*renderer)->setSeed(uint32_t(1000 + i));
            Status s = (*renderer)->setEnvironment(envAt(i));
            if (s) s = (*renderer)->reset();
            if (s) s = (*renderer)->render(isStill ? o.stillSpp : o.movingSpp);
            if (!s) {
                logError("frame {}: {}", i, s.message());
                return 1;
            }
            auto img = (*renderer)->image(Aov::Composite);
            if (!img) {
                logError("frame {}: {}", i, img.message());
                return 1;
            }
            linear = std::move(img).value();
            if (isStill) still = linear;
            logInfo(
                "frame {}/{}: rendered {} spp in {:.1f} s", i + 1, o.frames,
                isStill ? o.stillSpp : o.movingSpp,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        }
        int w = 0, h = 0;
        const std::vector<uint8_t> jpeg = encodeFrame(linear, uint64_t(7919 + i), w, h);
        if (Status s =
                writer->writeFrame("scene", uint64_t(i), t, jpeg, "jpg", uint32_t(w), uint32_t(h));
            !s) {
            logError("{}", s.message());
            return 1;
        }
        PoseRecord truth;
        truth.timestampNs = t;
        truth.frame = uint64_t(i);
        truth.kind = PoseKind::Truth;
        std::array<double, 16> m{};
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) m[size_t(r * 4 + c)] = pose(r, c);
        truth.worldFromCamera = m;
        if (Status s = writer->writePose(truth); !s) {
            logError("{}", s.message());
            return 1;
        }
        if (i % kFisheyeEvery == 0) {
            EnvironmentSampler sampler(*envAt(i));
            auto fish = fisheyeImage(*fisheyeCal, sampler, o.envScale);
            if (!fish) {
                logError("{}", fish.message());
                return 2;
            }
            if (i == 0) {
                float brightest = 0.0f;
                for (float v : fish->pixels) brightest = std::max(brightest, v);
                logInfo("fisheye: brightest pixel channel {:.1f} (box-filtered texels)", brightest);
            }
            // One frame per exposure, 1/30 s apart, each with its own sensor noise.
            for (size_t k = 0; k < o.bracketStops.size(); ++k) {
                FrameStamp stamp;
                stamp.exposureStops = o.bracketStops[k];
                const std::vector<uint8_t> fjpeg =
                    encodeFrame(*fish, uint64_t(104729 + i + 1000 * k), w, h, o.bracketStops[k]);
                if (Status s = writer->writeFrame("fisheye", fisheyeSeq++,
                                                  t + kFisheyeOffsetNs + k * kBracketFrameNs, fjpeg,
                                                  "jpg", uint32_t(w), uint32_t(h), stamp);
                    !s) {
                    logError("{}", s.message());
                    return 1;
                }
            }
        }
        // The mode button: into refinement shortly after the camera stops, back to preview
        // before it moves again.
        if (i == kStillFirst + 2 || i == kStillLast - 2) {
            if (Status s = writer->writeEvent({t + 20'000'000, "mode-button", "short-press"}); !s) {
                logError("{}", s.message());
                return 1;
            }
        }
    }
    if (Status s = writer->flush(); !s) {
        logError("{}", s.message());
        return 1;
    }
    if (Status s = copyDemoConfig(o.demoDir, sessionDir); !s) {
        logError("{}", s.message());
        return 1;
    }
    logInfo("wrote {}", sessionDir);
    if (o.truthSpp == 0) return 0;

    *renderer = nullptr;  // the plates' renderer gives its memory back before the truth's
    scene->geometry = std::move(wholeSet);
    TruthContext truth{o, *scene, **ctx, settings, *sceneCal, envAt};
    if (Status s = writeTruth(truth); !s) {
        logError("truth: {}", s.message());
        return 1;
    }
    logInfo("wrote {}/truth", o.demoDir);
    return 0;
}

}  // namespace
}  // namespace previs

int main(int argc, char** argv) {
    previs::Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&]() -> std::string {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "make_demo_session: %s needs a value\n", a.c_str());
                std::exit(2);
            }
            return argv[++i];
        };
        if (a == "--demo-dir")
            o.demoDir = next();
        else if (a == "--env")
            o.envPath = next();
        else if (a == "--env-scale")
            o.envScale = std::stof(next());
        else if (a == "--moving-spp")
            o.movingSpp = uint32_t(std::stoul(next()));
        else if (a == "--still-spp")
            o.stillSpp = uint32_t(std::stoul(next()));
        else if (a == "--max-depth")
            o.maxDepth = uint32_t(std::stoul(next()));
        else if (a == "--frames")
            o.frames = std::clamp(std::stoi(next()), 1, previs::kFrames);
        else if (a == "--bracket-stops" || a == "--truth-frames") {
            // A comma-separated list: "0,-4,-8".
            const std::string list = next();
            std::vector<float> v;
            for (size_t p = 0; p <= list.size();) {
                const size_t e = std::min(list.find(',', p), list.size());
                v.push_back(std::stof(list.substr(p, e - p)));
                p = e + 1;
            }
            if (a == "--bracket-stops") {
                o.bracketStops = v;
            } else {
                o.truthFrames.clear();
                for (float f : v)
                    o.truthFrames.push_back(std::clamp(int(f), 0, previs::kFrames - 1));
            }
        } else if (a == "--truth-spp")
            o.truthSpp = uint32_t(std::stoul(next()));
        else if (a == "--env-name")
            o.envName = next();
        else {
            std::fprintf(stderr,
                         "usage: make_demo_session --demo-dir examples/demo --env MAP.hdr "
                         "[--env-scale X] [--moving-spp N] [--still-spp N] [--max-depth N] "
                         "[--frames N] [--bracket-stops S1,S2,...] [--truth-frames F1,F2,...] "
                         "[--truth-spp N (0: no truth folder)] [--env-name NAME]\n");
            return a == "--help" ? 0 : 2;
        }
    }
    if (o.bracketStops.empty() || o.truthFrames.empty()) {
        std::fprintf(stderr, "make_demo_session: --bracket-stops and --truth-frames need values\n");
        return 2;
    }
    // A bracket ends before the next lighting instant.
    if (previs::kFisheyeOffsetNs + o.bracketStops.size() * previs::kBracketFrameNs >
        previs::kFisheyeEvery * previs::kFrameNs) {
        std::fprintf(stderr, "make_demo_session: at most %d --bracket-stops fit between instants\n",
                     int((previs::kFisheyeEvery * previs::kFrameNs - previs::kFisheyeOffsetNs) /
                         previs::kBracketFrameNs));
        return 2;
    }
    if (o.demoDir.empty() || o.envPath.empty()) {
        std::fprintf(stderr, "make_demo_session: --demo-dir and --env are required (--help)\n");
        return 2;
    }
    return previs::run(o);
}
