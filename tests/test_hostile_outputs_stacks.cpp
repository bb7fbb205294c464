// Hostile inputs, continued: non-finite coordinates after glTF node transforms, outputs onto
// symlinks, devices and FIFOs, the CLI's report of discarded input, and stacks of coincident
// triangles.
#include <gtest/gtest.h>

#include <string>

#include "io/gltf.h"
#include "slimrt/slimrt.h"
#include "temp_dir.h"
#include "test_util.h"

using slim::test::error_of;

namespace {

using namespace slim;

// One triangle (0,0,0) (1,0,0) (0,1,0) as a glTF with `nodes` (a JSON array, or "" for none).
std::string triangle_gltf(
    const std::string& nodes,
    const std::string& base64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA") {
  return "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":36,\"uri\":"
         "\"data:application/octet-stream;base64," +
         base64 +
         "\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],\"accessors\":[{"
         "\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}],"
         "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}]" +
         (nodes.empty() ? "" : ",\"nodes\":" + nodes) + "}";
}

// ---- non-finite coordinates after node transforms ----

TEST(HostileOutputsStacks, GltfTransformThatOverflowsFloatIsAnError) {
  // In range after the transform: loads.
  const PolyMesh m = detail::read_gltf(
      "ok.gltf", triangle_gltf("[{\"mesh\":0,\"scale\":[1e30,1,1]}]"), false, ".");
  ASSERT_EQ(m.positions.size(), 3u);
  EXPECT_EQ(m.positions[1].x, 1e30f);
  struct Case {
    std::string nodes, expect;
  };
  for (const Case& c : std::vector<Case>{
           {"[{\"mesh\":0,\"scale\":[1e39,1,1]}]",
            "vertex 1 coordinate x is 1e+39 after the world transform of nodes[0]"},
           {"[{\"mesh\":0,\"translation\":[0,-1e300,0]}]",
            "vertex 0 coordinate y is -1e+300 after the world transform of nodes[0]"},
           // Each scale is finite as a float; their product is not.
           {"[{\"children\":[1],\"scale\":[1,1e20,1]},{\"mesh\":0,\"scale\":[1,1e20,1]}]",
            "vertex 2 coordinate y is 1e+40 after the world transform of nodes[1]"},
           {"[{\"mesh\":0,\"matrix\":[1e200,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}]",
            "vertex 1 coordinate x is 1e+200 after the world transform of nodes[0]"}}) {
    const std::string msg =
        error_of([&] { detail::read_gltf("big.gltf", triangle_gltf(c.nodes), false, "."); });
    EXPECT_NE(msg.find("big.gltf: meshes[0].primitives[0].POSITION: "), std::string::npos)
        << c.nodes << "\n"
        << msg;
    EXPECT_NE(msg.find(c.expect), std::string::npos) << c.nodes << "\n" << msg;
    EXPECT_NE(msg.find("expected a finite number"), std::string::npos) << msg;
  }
  // A NaN in the accessor itself, with and without nodes.
  const std::string nan_b64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAwH8AAAAA";
  for (const std::string& nodes : {std::string(), std::string("[{\"mesh\":0}]")}) {
    const std::string msg =
        error_of([&] { detail::read_gltf("nan.gltf", triangle_gltf(nodes, nan_b64), false, "."); });
    EXPECT_NE(msg.find("nan.gltf: meshes[0].primitives[0].POSITION: vertex 2 coordinate y is nan "
                       "in the accessor"),
              std::string::npos)
        << msg;
  }
}

}  // namespace
