// The .mesh format, the default skin and glTF user meshes.
#include "render/skin.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "render/gltf_skin.h"

namespace caphub::render {
namespace {

using board::Segment;

// A two-triangle skin over two segments, one rigid group and one blended.
Skin tinySkin() {
    Skin s;
    s.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0.5f}};
    s.normals = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0.6f, 0.8f}};
    s.joints = {{4, 0, 0, 0}, {4, 0, 0, 0}, {7, 8, 0, 0}, {7, 8, 6, 0}};
    s.weights = {{1, 0, 0, 0}, {1, 0, 0, 0}, {0.75f, 0.25f, 0, 0}, {0.5f, 0.3f, 0.2f, 0}};
    s.triangles = {{0, 1, 2}, {1, 3, 2}};
    s.groups = {{"head", GroupMethod::Rigid, 4, 0, 2}, {"arm", GroupMethod::Dqs, 7, 2, 2}};
    s.jointOriginsM[4] = {0, 1.5f, 0};
    s.provenance = "test";
    return s;
}

TEST(SkinFormat, RoundTripKeepsPositionsExactlyAndQuantisedDataClose) {
    const Skin in = tinySkin();
    auto out = decodeSkin(encodeSkin(in), "memory");
    ASSERT_TRUE(out) << out.error().message;
    EXPECT_EQ(out->positions, in.positions);  // stored as float32
    EXPECT_EQ(out->triangles, in.triangles);
    EXPECT_EQ(out->joints, in.joints);
    ASSERT_EQ(out->groups.size(), 2u);
    EXPECT_EQ(out->groups[1].name, "arm");
    EXPECT_EQ(out->groups[1].method, GroupMethod::Dqs);
    EXPECT_EQ(out->jointOriginsM[4], in.jointOriginsM[4]);
    EXPECT_EQ(out->provenance, "test");
    for (std::size_t v = 0; v < in.positions.size(); ++v) {
        for (int k = 0; k < 3; ++k) {
            // int16 normals: steps of 1/32767.
            EXPECT_NEAR(out->normals[v][k], in.normals[v][k], 1.0 / 32767);
        }
        for (int k = 0; k < 4; ++k) {
            // uint8 weights: half a step of 1/255, then renormalised.
            EXPECT_NEAR(out->weights[v][k], in.weights[v][k], 0.6 / 255 + 1e-6);
        }
    }
}

TEST(SkinFormat, TruncatedFileIsRefusedWithWhatWasMissing) {
    auto bytes = encodeSkin(tinySkin());
    bytes.resize(bytes.size() - 5);
    auto out = decodeSkin(bytes, "cut.mesh");
    ASSERT_FALSE(out);
    EXPECT_NE(out.error().message.find("cut.mesh"), std::string::npos);
}

TEST(SkinFormat, WrongMagicIsRefused) {
    std::vector<std::uint8_t> bytes(64, 'x');
    auto out = decodeSkin(bytes, "junk.mesh");
    ASSERT_FALSE(out);
    EXPECT_NE(out.error().message.find("CAPHUBSK"), std::string::npos);
}

TEST(SkinFormat, EveryTruncationOfAValidFileIsAnErrorNotACrash) {
    const auto bytes = encodeSkin(tinySkin());
    for (std::size_t n = 0; n < bytes.size(); ++n) {
        std::vector<std::uint8_t> cut(bytes.begin(), bytes.begin() + static_cast<long>(n));
        EXPECT_FALSE(decodeSkin(cut, "cut.mesh")) << n;
    }
}

TEST(SkinValidation, RigidGroupWithABlendedVertexIsRefused) {
    Skin s = tinySkin();
    s.joints[1] = {4, 7, 0, 0};
    s.weights[1] = {0.5f, 0.5f, 0, 0};
    auto ok = validate(s);
    ASSERT_FALSE(ok);
    EXPECT_NE(ok.error().message.find("rigid group 'head'"), std::string::npos);
}

TEST(SkinValidation, TriangleIndexOutOfRangeIsRefused) {
    Skin s = tinySkin();
    s.triangles[1][2] = 9;
    EXPECT_FALSE(validate(s));
}

TEST(DefaultSkin, LoadsWithTheMakeHumanBodyAndAllGroups) {
    auto s = loadDefaultSkin();
    ASSERT_TRUE(s) << s.error().message;
    EXPECT_EQ(s->vertexCount(), 13380u);  // the hm08 body's vertex count
    EXPECT_EQ(s->groups.size(), 14u);
    for (const char* g : {"head", "l_hand", "r_hand", "l_foot", "r_foot", "l_toes", "r_toes"}) {
        const int i = s->findGroup(g);
        ASSERT_GE(i, 0) << g;
        EXPECT_EQ(s->groups[static_cast<std::size_t>(i)].method, GroupMethod::Rigid) << g;
        EXPECT_GT(s->groups[static_cast<std::size_t>(i)].vertexCount, 100u) << g;
    }
    EXPECT_EQ(s->groups[static_cast<std::size_t>(s->findGroup("l_forearm"))].method,
              GroupMethod::Dqs);
}

TEST(DefaultSkin, StandsInTheTPoseFacingPlusZWithTheLeftArmAlongPlusX) {
    auto s = loadDefaultSkin();
    ASSERT_TRUE(s) << s.error().message;
    float minY = 1e9f, maxY = -1e9f, maxX = -1e9f, minX = 1e9f;
    for (const auto& p : s->positions) {
        minY = std::min(minY, p[1]);
        maxY = std::max(maxY, p[1]);
        minX = std::min(minX, p[0]);
        maxX = std::max(maxX, p[0]);
    }
    EXPECT_NEAR(minY, 0.0f, 1e-4);   // feet on the floor
    EXPECT_NEAR(maxY, 1.67f, 0.05);  // MakeHuman's default height
    EXPECT_GT(maxX - minX, 1.4f);    // arms spread: the span is near the height
    const auto& lHand = s->jointOriginsM[static_cast<int>(Segment::LHand)];
    const auto& lShoulder = s->jointOriginsM[static_cast<int>(Segment::LUpperarm)];
    EXPECT_GT(lHand[0] - lShoulder[0], 0.45f);
    EXPECT_NEAR(lHand[1], lShoulder[1], 0.02f);  // arm horizontal (2 cm over ~0.5 m)
    const auto& lToes = s->jointOriginsM[static_cast<int>(Segment::LMiddistal)];
    const auto& lAnkle = s->jointOriginsM[static_cast<int>(Segment::LHindfoot)];
    EXPECT_GT(lToes[2], lAnkle[2]);  // toes point forward, +Z
}

TEST(GltfJointMapFile, BadLineNamesTheLine) {
    auto m = parseGltfJointMap("Hips = pelvis\nSpine pelvis\n", "map.txt");
    ASSERT_FALSE(m);
    EXPECT_NE(m.error().message.find("map.txt:2"), std::string::npos);
    auto u = parseGltfJointMap("Hips = hips\n", "map.txt");
    ASSERT_FALSE(u);
    EXPECT_NE(u.error().message.find("map.txt:1"), std::string::npos);
}

TEST(GltfSkin, CesiumManLoadsWithWeightsRenormalised) {
    auto map = parseGltfJointMap(
        // The model's nodes have no names: by index, from its hierarchy.
        "#2 = pelvis\n#11 = t12\n#12 = c7\n#19 = c7\n#20 = skull\n"
        "#13 = r_upperarm\n#14 = r_forearm\n#15 = r_hand\n"
        "#16 = l_upperarm\n#17 = l_forearm\n#18 = l_hand\n"
        "#3 = r_thigh\n#4 = r_calf\n#5 = r_hindfoot\n#6 = r_middistal\n"
        "#7 = l_thigh\n#8 = l_calf\n#9 = l_hindfoot\n#10 = l_middistal\n",
        "cesium.map");
    ASSERT_TRUE(map) << map.error().message;
    const auto path =
        std::filesystem::path(CAPHUB_SHARED_DATA_DIR) / "meshes" / "cesium_man_embedded.gltf";
    if (!std::filesystem::exists(path)) {
        GTEST_SKIP() << "shared data not beside the repository: " << path;
    }
    auto s = loadGltfSkin(path, *map);
    ASSERT_TRUE(s) << s.error().message;
    EXPECT_EQ(s->vertexCount(), 3273u);
    for (const auto& w : s->weights) {
        // The file's weights are not all normalised; validate() inside the loader checked
        // 1e-3, this checks float rounding only.
        EXPECT_NEAR(w[0] + w[1] + w[2] + w[3], 1.0f, 1e-5f);
    }
}

TEST(GltfSkin, MissingFileIsAnErrorNamingIt) {
    auto s = loadGltfSkin("/nonexistent/model.gltf", GltfJointMap{});
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("/nonexistent/model.gltf"), std::string::npos);
}

TEST(GltfSkin, NoMappedJointIsRefused) {
    GltfJointMap map;
    map.joints.emplace_back("no_such_joint", Segment::Pelvis);
    const auto path =
        std::filesystem::path(CAPHUB_SHARED_DATA_DIR) / "meshes" / "rigged_simple_embedded.gltf";
    if (!std::filesystem::exists(path)) {
        GTEST_SKIP() << "shared data not beside the repository: " << path;
    }
    auto s = loadGltfSkin(path, map);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("joint map"), std::string::npos);
}

}  // namespace
}  // namespace caphub::render
