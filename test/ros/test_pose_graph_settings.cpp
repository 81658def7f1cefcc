// The example back-end's settings (mild_lcd/PoseGraphNodelet, mild_lcd_pose_graph_node): declared once
// (src/ros/settings/pose_graph_settings.cpp and PoseGraphParams::declare), loaded type-checked and bounded,
// unknown names refused naming them; docs/pose_graph.md's table is that declaration.

#include <fstream>
#include <functional>
#include <iterator>
#include <string>

#include <gtest/gtest.h>

#include "../core/error_text.hpp"
#include "mild_lcd/params/parameter_source.hpp"
#include "mild_lcd/ros/settings/pose_graph_settings.hpp"

namespace mild_lcd {
namespace {

using mild::test::errorOf;

PoseGraphSettings from(const std::string& yaml) {
  return PoseGraphSettings::load(mild::YamlParameterSource::fromString(yaml));
}

TEST(PoseGraphSettings, DefaultsAndValues) {
  const PoseGraphSettings d = from("");
  EXPECT_TRUE(d.use_odometry_topic);
  EXPECT_EQ(d.base_frame, "base_link");
  EXPECT_EQ(d.graph.robust_loss, "cauchy");
  const PoseGraphSettings s = from(
      "use_odometry_topic: false\nbase_frame: robot\ntf_rate: 5.0\ngraph:\n  robust_loss: huber\n  max_iterations: "
      "7\n");
  EXPECT_FALSE(s.use_odometry_topic);
  EXPECT_EQ(s.base_frame, "robot");
  EXPECT_DOUBLE_EQ(s.tf_rate, 5.0);
  EXPECT_EQ(s.graph.robust_loss, "huber");
  EXPECT_EQ(s.graph.max_iterations, 7);
}

TEST(PoseGraphSettings, BadValuesAreRefusedNamingTheParameter) {
  const std::string typo = errorOf([] { from("base_fame: robot\n"); });
  EXPECT_NE(typo.find("~base_fame"), std::string::npos) << typo;
  EXPECT_NE(typo.find("base_frame"), std::string::npos) << "lists the real names: " << typo;
  EXPECT_NE(errorOf([] { from("tf_rate: 0\n"); }).find("tf_rate"), std::string::npos);
  EXPECT_NE(errorOf([] { from("odometry_wait: -1\n"); }).find("odometry_wait"), std::string::npos);
  EXPECT_NE(errorOf([] { from("publish_tf: \"yes\"\n"); }).find("publish_tf"), std::string::npos)
      << "a string where a boolean belongs";
  EXPECT_NE(errorOf([] { from("map_frame: \"\"\n"); }).find("map_frame"), std::string::npos);
  EXPECT_NE(errorOf([] { from("graph:\n  robust_loss: tukey\n"); }).find("robust_loss"), std::string::npos);
  EXPECT_NE(errorOf([] { from("graph:\n  max_iterations: 0\n"); }).find("max_iterations"), std::string::npos);
  EXPECT_NE(errorOf([] { from("graph:\n  loop_sigma: 1\n"); }).find("graph/loop_sigma"), std::string::npos);
}

TEST(PoseGraphSettings, TheDocsTableIsTheDeclaration) {
  std::ifstream in(std::string(MILD_SOURCE_DIR) + "/docs/pose_graph.md");
  const std::string page((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(page.find(poseGraphSettingsMarkdown()), std::string::npos)
      << "docs/pose_graph.md's parameter table is out of date; `mild_lcd_pose_graph_node --help-parameters` prints "
         "it:\n"
      << poseGraphSettingsMarkdown();
}

}  // namespace
}  // namespace mild_lcd
