// Wire scenes (protocol/palpate.capnp) and scene files share one validator:
// protocol/scene_wire.h turns a wire scene into scene-file JSON.
#include <capnp/message.h>
#include <capnp/schema.h>
#include <gtest/gtest.h>

#include "core/laws/laws.h"
#include "core/scene.h"
#include "protocol/scene_wire.h"

namespace palpate {
namespace {

TEST(SceneWire, DefaultWireSceneIsTheEmptyJsonObject) {
  capnp::MallocMessageBuilder mb;
  auto scene = mb.initRoot<wire::Scene>();
  scene.initMaterial();  // a set but default-valued section adds nothing
  EXPECT_EQ(scene_to_json(scene), "{\"material\":{}}");
  const Scene s = scene_from_wire(scene, "<rpc scene>", ".");
  const Scene d = parse_scene("{}", "<rpc scene>", ".");
  EXPECT_EQ(s.material.young_modulus, d.material.young_modulus);
  EXPECT_EQ(s.distribution.per_edge, d.distribution.per_edge);
  EXPECT_EQ(s.fixed_faces, d.fixed_faces);
  EXPECT_FALSE(s.indenter.position_given);
}

TEST(SceneWire, SnakeCaseNamesAndEnumerants) {
  capnp::MallocMessageBuilder mb;
  auto scene = mb.initRoot<wire::Scene>();
  auto dist = scene.initBody().initDistribution();
  dist.setType(wire::DistributionType::JITTERED_GRID);
  dist.setPerEdge(7);
  scene.initIntegrator().setType(wire::IntegratorType::SYMPLECTIC_EULER);
  auto fixed = scene.initFixed(2);
  fixed.set(0, wire::Face::BOTTOM);
  fixed.set(1, wire::Face::X_MIN);
  const std::string json = scene_to_json(scene);
  EXPECT_NE(json.find("\"per_edge\":7"), std::string::npos) << json;
  EXPECT_NE(json.find("\"jittered_grid\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"symplectic_euler\""), std::string::npos) << json;
  EXPECT_NE(json.find("\"x_min\""), std::string::npos) << json;
  const Scene s = scene_from_wire(scene, "<rpc scene>", ".");
  EXPECT_EQ(s.distribution.type, DistributionType::jittered_grid);
  EXPECT_EQ(s.distribution.per_edge, 7);
  EXPECT_EQ(s.integrator.type, IntegratorType::symplectic_euler);
  EXPECT_EQ(s.fixed_faces, face_bottom | face_x_min);
}

TEST(SceneWire, SceneFileRoundTripsThroughTheWire) {
  const Scene file = load_scene(PALPATE_SOURCE_DIR "/scenes/hertz_cube.json");
  // JSON file -> wire struct -> JSON -> Scene.
  std::string text;
  {
    std::FILE* f = std::fopen(PALPATE_SOURCE_DIR "/scenes/hertz_cube.json", "rb");
    ASSERT_NE(f, nullptr);
    char buf[4096];
    for (size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) text.append(buf, n);
    std::fclose(f);
  }
  capnp::MallocMessageBuilder mb;
  auto scene = mb.initRoot<wire::Scene>();
  scene_json_to_wire(text, "hertz_cube.json", scene);
  const Scene wire = scene_from_wire(scene, "hertz_cube", PALPATE_SOURCE_DIR "/scenes");
  EXPECT_EQ(wire.name, file.name);
  EXPECT_EQ(wire.distribution.per_edge, file.distribution.per_edge);
  EXPECT_EQ(wire.mls.volumes, file.mls.volumes);
  EXPECT_EQ(wire.integrator.damping, file.integrator.damping);
  EXPECT_EQ(wire.verify.forces, file.verify.forces);
  EXPECT_EQ(wire.box.min, file.box.min);
  EXPECT_EQ(wire.fixed_faces, file.fixed_faces);
}

// The material law and the hex FEM's volumetric integration cross the wire.
TEST(SceneWire, MaterialLawAndVolumetricIntegrationRoundTrip) {
  capnp::MallocMessageBuilder mb;
  auto scene = mb.initRoot<wire::Scene>();
  scene_json_to_wire(R"({"material": {"law": "corotational"}, "hex_fem": {"volumetric_integration": "reduced"}})",
                     "t.json", scene);
  EXPECT_EQ(scene.getMaterial().getLaw(), wire::MaterialLaw::COROTATIONAL);
  EXPECT_EQ(scene.getHexFem().getVolumetricIntegration(), wire::HexVolumetricIntegration::REDUCED);
  const Scene s = scene_from_wire(scene, "<rpc scene>", ".");
  EXPECT_EQ(s.material.law, MaterialLaw::corotational);
  EXPECT_EQ(s.hex_fem.volumetric_integration, HexVolumetricIntegration::reduced);
  capnp::MallocMessageBuilder mb_neo;
  auto neo = mb_neo.initRoot<wire::Scene>();
  scene_json_to_wire(R"({"material": {"law": "neo_hookean"}})", "t.json", neo);
  EXPECT_EQ(neo.getMaterial().getLaw(), wire::MaterialLaw::NEO_HOOKEAN);
  EXPECT_EQ(scene_from_wire(neo, "<rpc scene>", ".").material.law, MaterialLaw::neo_hookean);
}

// Every material law of the one list (core/laws/laws.h) crosses the wire by its name, and the
// wire's MaterialLaw has no law the list lacks: adding a law to one and not the other fails here.
TEST(SceneWire, TheWireHasEveryMaterialLawAndNoOther) {
  EXPECT_EQ(capnp::Schema::from<wire::MaterialLaw>().getEnumerants().size(),
            static_cast<unsigned>(mls::MaterialLaws::size));
  for (const auto& [name, id] : mls::material_law_names) {
    SCOPED_TRACE(std::string(name));
    capnp::MallocMessageBuilder mb;
    auto scene = mb.initRoot<wire::Scene>();
    scene_json_to_wire(R"({"material": {"law": ")" + std::string(name) + R"("}})", "t.json", scene);
    EXPECT_EQ(scene_from_wire(scene, "<rpc scene>", ".").material.law, id);
    EXPECT_STREQ(to_string(id), std::string(name).c_str());
  }
}

// The health checks and the envelope override cross the wire too, with the file's validation.
TEST(SceneWire, HealthAndAllowUnstableDtRoundTrip) {
  capnp::MallocMessageBuilder mb;
  auto scene = mb.initRoot<wire::Scene>();
  scene_json_to_wire(R"({"health": {"enabled": false, "energy_factor": 4, "inversion_sweep_ticks": 8},
                         "integrator": {"allow_unstable_dt": true}})",
                     "t.json", scene);
  EXPECT_FALSE(scene.getHealth().getEnabled());
  EXPECT_TRUE(scene.getIntegrator().getAllowUnstableDt());
  const Scene s = scene_from_wire(scene, "<rpc scene>", ".");
  EXPECT_FALSE(s.health.enabled);
  EXPECT_EQ(s.health.energy_factor, 4.0);
  EXPECT_EQ(s.health.inversion_sweep_ticks, 8);
  EXPECT_TRUE(s.integrator.allow_unstable_dt);
  capnp::MallocMessageBuilder bad;
  auto b = bad.initRoot<wire::Scene>();
  b.initHealth().setEnergyFactor(0.5);
  try {
    scene_from_wire(b, "<rpc scene>", ".");
    FAIL() << "an energy factor below 1 was accepted";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/health/energy_factor");
  }
}

// The mesh distribution (Distribution.file, VolumeRule mesh): JSON -> wire -> JSON
// keeps the file name and the volume rule.
TEST(SceneWire, MeshDistributionRoundTrips) {
  const std::string text = R"({"body": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]},
      "distribution": {"type": "mesh", "file": "cube_tet_small.msh"}}, "mls": {"volumes": "mesh"}})";
  capnp::MallocMessageBuilder mb;
  auto scene = mb.initRoot<wire::Scene>();
  scene_json_to_wire(text, "mesh.json", scene);
  EXPECT_EQ(scene.getBody().getDistribution().getType(), wire::DistributionType::MESH);
  EXPECT_EQ(std::string(scene.getBody().getDistribution().getFile().cStr()), "cube_tet_small.msh");
  EXPECT_EQ(scene.getMls().getVolumes(), wire::VolumeRule::MESH);
  const std::string json = scene_to_json(scene);
  EXPECT_NE(json.find("\"file\":\"cube_tet_small.msh\""), std::string::npos) << json;
  const Scene s = scene_from_wire(scene, "<rpc scene>", PALPATE_SOURCE_DIR "/tests/data");
  EXPECT_EQ(s.distribution.type, DistributionType::mesh);
  EXPECT_EQ(s.mls.volumes, VolumeRule::mesh);
  EXPECT_EQ(s.distribution.mesh_file.filename(), "cube_tet_small.msh");
}

// Text crosses the wire byte for byte; JSON text must be UTF-8. A client's bad bytes are
// refused with the field's pointer, and every well-formed sequence passes.
TEST(SceneWire, TextThatIsNotUtf8IsRefusedAtItsField) {
  const auto error_of = [](const char* node_file, const char* group) -> std::string {
    capnp::MallocMessageBuilder mb;
    auto scene = mb.initRoot<wire::Scene>();
    auto d = scene.initBody().initDistribution();
    d.setType(wire::DistributionType::NODE_FILE);
    d.setNodeFile(node_file);
    if (group != nullptr) scene.getMaterial().initInclusions(2)[1].setGroup(group);
    try {
      scene_to_json(scene);
    } catch (const SceneError& e) {
      return e.field() + ": " + e.reason();
    }
    return "";
  };
  // Well-formed: ASCII, 2-, 3- and 4-byte sequences at the edges of their ranges.
  for (const char* good : {"nodes.txt", "n\xc3\xb6" "des", "\xe0\xa0\x80\xed\x9f\xbf\xef\xbf\xbf", "\xf0\x90\x80\x80\xf4\x8f\xbf\xbf"})
    EXPECT_EQ(error_of(good, "tumour"), "") << good;
  // A truncated sequence, a lone continuation byte, overlong forms, a surrogate, beyond U+10FFFF.
  for (const char* bad : {"\xe2" "ex_fe", "a\x80", "\xc0\xaf", "\xe0\x9f\xbf", "\xed\xa0\x80", "\xf4\x90\x80\x80", "\xc3"})
    EXPECT_EQ(error_of(bad, nullptr), "/body/distribution/node_file: the text is not valid UTF-8") << bad;
  EXPECT_EQ(error_of("nodes.txt", "\xff"), "/material/inclusions/1/group: the text is not valid UTF-8");
}

TEST(SceneWire, ErrorsNameTheField) {
  capnp::MallocMessageBuilder mb;
  auto scene = mb.initRoot<wire::Scene>();
  scene.initContact().setMaxIterations(0);
  try {
    scene_from_wire(scene, "<rpc scene>", ".");
    FAIL() << "accepted max_iterations = 0";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/contact/max_iterations");
    EXPECT_EQ(e.source(), "<rpc scene>");
  }
  scene.initContact();
  scene.initIndenter().setRadius(INFINITY);  // encoded as the string "Infinity": refused at its field
  try {
    scene_from_wire(scene, "<rpc scene>", ".");
    FAIL() << "accepted an infinite radius";
  } catch (const SceneError& e) {
    EXPECT_EQ(e.field(), "/indenter/radius");
  }
}

}  // namespace
}  // namespace palpate
