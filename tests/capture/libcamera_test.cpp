// The libcamera source without a camera: choosing the camera and the pixel format, the mapping
// of libcamera's format names onto the conversions (byte order included), and the messages a
// user sees when libcamera finds nothing. The device path runs in libcamera_vm_test.cpp.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "capture/libcamera_camera.h"
#include "capture/pixel_format.h"

namespace previs {
namespace {

bool contains(const std::string& haystack, const std::string& needle) {
    return haystack.find(needle) != std::string::npos;
}

const std::vector<std::string> kIds = {"/base/soc/i2c0mux/i2c@1/imx477@1a",
                                       "/base/soc/i2c0mux/i2c@0/ov5647@36",
                                       "\\_SB_.PCI0.XHC_.RHUB.HS05-5:1.0-046d:0825"};

TEST(LibcameraSelect, CameraByIdIndexOrUniquePart) {
    EXPECT_EQ(*selectLibcameraCamera("", kIds), 0u);
    EXPECT_EQ(*selectLibcameraCamera(kIds[1], kIds), 1u);
    EXPECT_EQ(*selectLibcameraCamera("2", kIds), 2u);
    EXPECT_EQ(*selectLibcameraCamera("imx477", kIds), 0u);
    EXPECT_EQ(*selectLibcameraCamera("046d:0825", kIds), 2u);
}

TEST(LibcameraSelect, UnknownOrAmbiguousCameraListsTheCameras) {
    Result<size_t> r = selectLibcameraCamera("imx219", kIds);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.message(), "libcamera camera 'imx219': no such camera")) << r.message();
    // Every camera with its index, so the user can copy one into the config.
    EXPECT_TRUE(contains(r.message(), "0 '/base/soc/i2c0mux/i2c@1/imx477@1a'")) << r.message();
    EXPECT_TRUE(contains(r.message(), "2 '\\_SB_")) << r.message();

    r = selectLibcameraCamera("3", kIds);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.message(), "'3': no such camera")) << r.message();

    r = selectLibcameraCamera("i2c0mux", kIds);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.message(), "matches several cameras")) << r.message();
}

TEST(LibcameraSelect, NoCamerasAtAll) {
    Result<size_t> r = selectLibcameraCamera("", {});
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.message(), "first libcamera camera: libcamera found no cameras"))
        << r.message();
    EXPECT_TRUE(contains(r.message(), "cam -l")) << r.message();
    r = selectLibcameraCamera("imx477", {});
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.message(), "'imx477': libcamera found no cameras")) << r.message();
}

// DRM fourccs as libcamera spells them, built here from their characters so the test does not
// share the table it checks.
uint32_t drm(const char* name) { return fourccFromString(name); }

TEST(LibcameraFormats, MapOntoConversions) {
    EXPECT_EQ(v4l2FourccFromLibcamera(drm("YUYV"), 0), fourccFromString("YUYV"));
    EXPECT_EQ(v4l2FourccFromLibcamera(drm("NV12"), 0), fourccFromString("NV12"));
    EXPECT_EQ(v4l2FourccFromLibcamera(drm("YU12"), 0), fourccFromString("YU12"));
    EXPECT_EQ(v4l2FourccFromLibcamera(drm("MJPG"), 0), fourccFromString("MJPG"));
    EXPECT_EQ(v4l2FourccFromLibcamera(drm("R8"), 0), fourccFromString("GREY"));
    // Raw Bayer (SRGGB10) and a vendor modifier (Raspberry Pi's packed/compressed layouts).
    EXPECT_EQ(v4l2FourccFromLibcamera(drm("RG10"), 0), 0u);
    EXPECT_EQ(v4l2FourccFromLibcamera(drm("YUYV"), uint64_t(7) << 56 | 1), 0u);
}

// DRM formats name the bits of a little-endian word, high to low: BGR888 is B in bits 23:16,
// so the bytes in memory are R, G, B. A swap here would turn a red set blue.
TEST(LibcameraFormats, RgbByteOrderInMemory) {
    struct Case {
        const char* name;
        std::vector<uint8_t> pixel;  // one pure red pixel as the camera writes it
    };
    const Case cases[] = {{"BG24", {255, 0, 0}},      // BGR888
                          {"RG24", {0, 0, 255}},      // RGB888
                          {"XR24", {0, 0, 255, 0}},   // XRGB8888
                          {"XB24", {255, 0, 0, 0}}};  // XBGR8888
    for (const Case& c : cases) {
        const uint32_t fourcc = v4l2FourccFromLibcamera(drm(c.name), 0);
        ASSERT_NE(fourcc, 0u) << c.name;
        std::vector<uint8_t> rgb;
        ASSERT_TRUE(convertToRgb(fourcc, c.pixel, 1, 1, 0, rgb)) << c.name;
        EXPECT_EQ(rgb, (std::vector<uint8_t>{255, 0, 0})) << c.name;
    }
}

TEST(LibcameraFormats, SelectPreferredThenConvertible) {
    const std::vector<OfferedFormat> offered = {{"SRGGB10_CSI2P", 0},
                                                {"XRGB8888", fourccFromString("XR24")},
                                                {"YUV420", fourccFromString("YU12")}};
    EXPECT_EQ(*selectLibcameraFormat("cam", "", offered, 2), 2u);  // the camera's preference
    EXPECT_EQ(*selectLibcameraFormat("cam", "", offered, 0), 1u);  // raw: first convertible
    EXPECT_EQ(*selectLibcameraFormat("cam", "yuv420", offered, 1), 2u);

    Result<size_t> r = selectLibcameraFormat("cam", "NV12", offered, 2);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.message(),
                         "libcamera camera 'cam': does not offer pixel format NV12; it offers: "
                         "SRGGB10_CSI2P, XRGB8888, YUV420"))
        << r.message();

    r = selectLibcameraFormat("cam", "SRGGB10_CSI2P", offered, 2);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.message(), "SRGGB10_CSI2P cannot be converted to RGB")) << r.message();
    EXPECT_TRUE(contains(r.message(), "BGR888")) << r.message();

    r = selectLibcameraFormat("cam", "", {{"SRGGB10_CSI2P", 0}}, 0);
    ASSERT_FALSE(r);
    EXPECT_TRUE(contains(r.message(), "none of its pixel formats (SRGGB10_CSI2P)")) << r.message();
}

// The real CameraManager on a machine without cameras (the build host): the message a user
// gets, twice, so the process-wide manager is also built again after the first one stopped.
TEST(LibcameraCamera, NoCameraOnThisMachine) {
    Result<std::vector<LibcameraCameraInfo>> cameras = listLibcameraCameras();
    ASSERT_TRUE(cameras) << cameras.message();
    if (!cameras->empty()) GTEST_SKIP() << "this machine has a camera: " << cameras->front().id;
    for (const char* wanted : {"", "imx477"}) {
        LibcameraConfig config;
        config.camera = wanted;
        auto camera = LibcameraCamera::create(config);
        ASSERT_FALSE(camera);
        EXPECT_TRUE(contains(camera.message(), "libcamera found no cameras")) << camera.message();
        if (*wanted) {
            EXPECT_TRUE(contains(camera.message(), "'imx477'")) << camera.message();
        }
    }
}

}  // namespace
}  // namespace previs
