#include <gtest/gtest.h>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include "core/cv_bridge.h"
#include "mr/error.h"
#include "mr/image.h"
#include "core/oiio_bridge.h"
#include "test_support.h"

namespace mr {
namespace {

TEST(Image, ConstructsZeroFilledWithDefaultChannelNames) {
  Image im(4, 3, 3);
  EXPECT_EQ(im.width(), 4);
  EXPECT_EQ(im.height(), 3);
  EXPECT_EQ(im.channels(), 3);
  EXPECT_EQ(im.pixels().size(), 36u);
  EXPECT_EQ(im.channel_names(), (std::vector<std::string>{"R", "G", "B"}));
  for (float v : im.pixels()) EXPECT_EQ(v, 0.0f);
  EXPECT_EQ(Image(2, 2, 1).channel_names(), std::vector<std::string>{"Y"});
}

TEST(Image, RejectsAbsurdSizes) {
  EXPECT_THROW(Image(0, 10, 3), Error);
  EXPECT_THROW(Image(10, -1, 3), Error);
  EXPECT_THROW(Image(10, 10, 0), Error);
  EXPECT_THROW(Image(1 << 20, 1 << 20, 3), Error);  // 2^40 pixels
  try {
    Image(-5, 10, 3);
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument);
    EXPECT_NE(std::string(e.what()).find("-5x10x3"), std::string::npos) << e.what();
  }
}

TEST(Image, ViewsShareMemoryAndSubViewsAddress) {
  Image im = test::make_test_photo(8, 6);
  ImageView v = im.view();
  EXPECT_EQ(v.data, im.data());
  EXPECT_TRUE(v.contiguous());
  ImageView s = v.sub({2, 1, 3, 4});
  EXPECT_FALSE(s.contiguous());
  EXPECT_EQ(&s.at(0, 0, 1), &im.at(2, 1, 1));
  EXPECT_EQ(&s.at(2, 3, 2), &im.at(4, 4, 2));
  s.at(1, 1, 0) = 42.0f;
  EXPECT_EQ(im.at(3, 2, 0), 42.0f);
  EXPECT_THROW(v.sub({6, 0, 3, 1}), Error);
  Image copy = to_image(s);
  EXPECT_EQ(copy.width(), 3);
  EXPECT_EQ(copy.at(1, 1, 0), 42.0f);
}

TEST(Image, CopyIsDeepMoveIsFree) {
  Image a = test::make_test_photo(4, 4);
  a.metadata().set("Make", std::string("TestCam"));
  Image b = a;
  b.at(0, 0, 0) = 7.0f;
  EXPECT_NE(a.at(0, 0, 0), 7.0f);
  EXPECT_EQ(b.metadata().get_string("Make"), "TestCam");
  const float* p = a.data();
  Image c = std::move(a);
  EXPECT_EQ(c.data(), p);
}

TEST(Image, SelectChannels) {
  Image im(2, 2, 4);
  im.at(1, 1, 3) = 0.5f;
  im.at(1, 1, 0) = 0.25f;
  const int pick[] = {3, 0};
  Image s = im.select_channels(pick);
  EXPECT_EQ(s.channels(), 2);
  EXPECT_EQ(s.channel_names(), (std::vector<std::string>{"A", "R"}));
  EXPECT_EQ(s.at(1, 1, 0), 0.5f);
  EXPECT_EQ(s.at(1, 1, 1), 0.25f);
  const int bad[] = {4};
  EXPECT_THROW(im.select_channels(bad), Error);
}

TEST(Metadata, TypedValuesReadAsTextAndNumbers) {
  Metadata m;
  m.set("Make", std::string("Canon"));
  m.set("Exif:FocalLengthIn35mmFormat", 28.0);
  EXPECT_EQ(m.get_string("Make"), "Canon");
  EXPECT_EQ(m.get_number("Make"), std::nullopt);
  EXPECT_DOUBLE_EQ(*m.get_number("Exif:FocalLengthIn35mmFormat"), 28.0);
  EXPECT_FALSE(m.contains("Model"));
  m.erase("Make");
  EXPECT_FALSE(m.contains("Make"));
  // EXIF rationals (e.g. exposure time 1/250) come through as their value.
  m.impl().attributes.attribute("ExposureTime", detail::kTypeRational, std::array<int, 2>{1, 250}.data());
  EXPECT_NEAR(*m.get_number("ExposureTime"), 0.004, 1e-12);
  // Integer types (OIIO 2.4's get_float_indexed reads INT as 0).
  m.impl().attributes.attribute("Orientation", 6);
  EXPECT_EQ(m.get_number("Orientation"), 6.0);
  m.impl().attributes.attribute("Exif:ISO", detail::kTypeUInt16, std::array<std::uint16_t, 1>{400}.data());
  EXPECT_EQ(m.get_number("Exif:ISO"), 400.0);
}

TEST(ImageBridges, OiioWrapsWithoutCopying) {
  Image im = test::make_test_photo(16, 8);
  OIIO::ImageBuf buf = detail::wrap(im.view());
  EXPECT_EQ(buf.localpixels(), static_cast<void*>(im.data()));
  EXPECT_EQ(buf.spec().width, 16);
  float px[3];
  buf.getpixel(5, 3, px);
  EXPECT_EQ(px[0], im.at(5, 3, 0));
  EXPECT_EQ(px[2], im.at(5, 3, 2));
  // A strided sub-view wraps too and reads the right pixels.
  OIIO::ImageBuf sub = detail::wrap(im.view().sub({4, 2, 6, 3}));
  sub.getpixel(1, 1, px);
  EXPECT_EQ(px[1], im.at(5, 3, 1));
  // Writes through OIIO land in the mr::Image.
  OIIO::ImageBufAlgo::fill(buf, {0.25f, 0.5f, 0.75f});
  EXPECT_EQ(im.at(15, 7, 1), 0.5f);
}

TEST(ImageBridges, OpenCvMatSharesMemory) {
  Image im = test::make_test_photo(10, 7);
  cv::Mat m = detail::as_mat(im.view());
  EXPECT_EQ(static_cast<void*>(m.data), static_cast<void*>(im.data()));
  EXPECT_EQ(m.type(), CV_32FC3);
  EXPECT_EQ(m.at<cv::Vec3f>(4, 6)[2], im.at(6, 4, 2));
  cv::Mat sub = detail::as_mat(im.view().sub({2, 3, 4, 2}));
  EXPECT_EQ(sub.at<cv::Vec3f>(1, 1)[0], im.at(3, 4, 0));
  ImageView back = detail::as_view(sub);
  EXPECT_EQ(back.data, &im.at(2, 3, 0));
  EXPECT_EQ(back.row_stride, im.row_stride());
}

}  // namespace
}  // namespace mr
