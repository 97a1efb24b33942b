// The server's validation of client requests (server/requests.h), in particular
// which node files a client may name (a client could otherwise make a session
// thread read /dev/zero until memory runs out, block on a FIFO, or have the
// first line of any readable file echoed in the error message).
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <capnp/message.h>
#include <gtest/gtest.h>
#include <kj/exception.h>

#include "protocol/palpate.capnp.h"
#include "server/requests.h"

namespace palpate::server {
namespace {

namespace fs = std::filesystem;

class ServerRequests : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("palpate-requests-" + std::to_string(getpid()));
    fs::create_directories(dir_ / "scenes");
    options_.scene_dir = dir_ / "scenes";
    options_.default_scene = dir_ / "scenes" / "default.json";
    std::ofstream(options_.default_scene) << R"({"body": {"distribution": {"per_edge": 4}}})";
    std::ofstream nodes(dir_ / "scenes" / "nodes.txt");
    for (int k = 0; k < 8; ++k) nodes << (k & 1) << ' ' << (k >> 1 & 1) << ' ' << (k >> 2 & 1) - 1 << '\n';
    std::ofstream(dir_ / "outside.txt") << "0 0 0\n";
    // A TetGen cube (the six Kuhn tetrahedra) inside the scene folder, and copies outside it.
    std::ofstream node(dir_ / "scenes" / "cube.node");
    node << "8 3 0 0\n";
    for (int k = 0; k < 8; ++k) node << k << ' ' << (k & 1) << ' ' << (k >> 1 & 1) << ' ' << (k >> 2 & 1) - 1 << '\n';
    node.close();
    std::ofstream(dir_ / "scenes" / "cube.ele") << "6 4 0\n0 0 1 3 7\n1 0 5 1 7\n2 0 3 2 7\n3 0 2 6 7\n4 0 4 5 7\n5 0 6 4 7\n";
    fs::copy_file(dir_ / "scenes" / "cube.node", dir_ / "outside.node");
    fs::copy_file(dir_ / "scenes" / "cube.ele", dir_ / "outside.ele");
  }
  void TearDown() override { fs::remove_all(dir_); }

  // The error of opening an inline scene whose distribution is the node file `file`, or "".
  std::string open_node_file(const std::string& file) {
    capnp::MallocMessageBuilder mb;
    auto request = mb.initRoot<wire::OpenRequest>();
    auto d = request.getScene().initInlineScene().initBody().initDistribution();
    d.setType(wire::DistributionType::NODE_FILE);
    d.setNodeFile(file);
    try {
      session_scene(request, options_);
    } catch (const kj::Exception& e) {
      return e.getDescription().cStr();
    }
    return "";
  }

  // The same for a "mesh" distribution naming `file`.
  std::string open_mesh(const std::string& file) {
    capnp::MallocMessageBuilder mb;
    auto request = mb.initRoot<wire::OpenRequest>();
    auto scene = request.getScene().initInlineScene();
    auto d = scene.initBody().initDistribution();
    d.setType(wire::DistributionType::MESH);
    d.setFile(file);
    scene.initMls().setVolumes(wire::VolumeRule::MESH);
    try {
      session_scene(request, options_);
    } catch (const kj::Exception& e) {
      return e.getDescription().cStr();
    }
    return "";
  }

  fs::path dir_;
  ServerOptions options_;
};

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST_F(ServerRequests, NodeFileInsideTheSceneFolderIsAccepted) {
  EXPECT_EQ(open_node_file("nodes.txt"), "");
  EXPECT_EQ(open_node_file((dir_ / "scenes" / "nodes.txt").string()), "");
}

TEST_F(ServerRequests, NodeFileOutsideTheSceneFolderIsRefused) {
  for (const std::string file : {"/dev/zero", "../outside.txt", "/etc/passwd", "/proc/self/environ"}) {
    const std::string e = open_node_file(file);
    EXPECT_TRUE(contains(e, "/body/distribution/node_file")) << e;
    EXPECT_TRUE(contains(e, "outside the server's scene folder")) << file << ": " << e;
  }
}

TEST_F(ServerRequests, NodeFileThatIsNotARegularFileIsRefused) {
  fs::create_symlink("/dev/zero", dir_ / "scenes" / "zero.txt");  // resolved: outside
  EXPECT_TRUE(contains(open_node_file("zero.txt"), "outside the server's scene folder"));
  ASSERT_EQ(mkfifo((dir_ / "scenes" / "fifo.txt").c_str(), 0600), 0);
  EXPECT_TRUE(contains(open_node_file("fifo.txt"), "is not a regular file"));
}

TEST_F(ServerRequests, MeshFileInsideTheSceneFolderIsAccepted) {
  EXPECT_EQ(open_mesh("cube.node"), "");
  EXPECT_EQ(open_mesh((dir_ / "scenes" / "cube.node").string()), "");
}

TEST_F(ServerRequests, MeshFileOutsideTheSceneFolderIsRefused) {
  const std::string e = open_mesh("../outside.node");
  EXPECT_TRUE(contains(e, "/body/distribution/file")) << e;
  EXPECT_TRUE(contains(e, "outside the server's scene folder")) << e;
  // A .node inside whose .ele leads outside.
  fs::copy_file(dir_ / "scenes" / "cube.node", dir_ / "scenes" / "linked.node");
  fs::create_symlink(dir_ / "outside.ele", dir_ / "scenes" / "linked.ele");
  const std::string linked = open_mesh("linked.node");
  EXPECT_TRUE(contains(linked, "linked.ele' is outside the server's scene folder")) << linked;
}

TEST_F(ServerRequests, MeshBeyondTheParticleLimitIsRefusedBeforeItIsRead) {
  options_.max_particles = 7;
  const std::string e = open_mesh("cube.node");
  EXPECT_TRUE(contains(e, "/body/distribution/file: the mesh declares 8 nodes, beyond this server's limit")) << e;
  options_.max_particles = 8;
  EXPECT_EQ(open_mesh("cube.node"), "");
  std::ofstream(dir_ / "scenes" / "bad.msh") << "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 many\n";
  const std::string bad = open_mesh("bad.msh");
  EXPECT_TRUE(contains(bad, "bad.msh:5: numNodes: expected an integer, got 'many'")) << bad;
}

TEST_F(ServerRequests, NodeFileBeyondTheParticleLimitIsRefusedBeforeItIsRead) {
  options_.max_particles = 7;  // nodes.txt lists 8
  const std::string e = open_node_file("nodes.txt");
  EXPECT_TRUE(contains(e, "/body/distribution/node_file: '")) << e;
  EXPECT_TRUE(contains(e, "nodes.txt' lists more than 7 nodes, this server's particle limit "
                          "(palpate-server --max-particles)"))
      << e;
  options_.max_particles = 8;
  EXPECT_EQ(open_node_file("nodes.txt"), "");
  // Blank lines and comments are not nodes (the node list format, core/node_cloud.h).
  {
    std::ofstream f(dir_ / "scenes" / "commented.txt");
    f << "# a cube\n\n   \n\t# indented comment\r\n";
    for (int k = 0; k < 8; ++k) f << "  " << (k & 1) << ' ' << (k >> 1 & 1) << ' ' << (k >> 2 & 1) - 1 << "\r\n";
    f << "# end";
  }
  EXPECT_EQ(open_node_file("commented.txt"), "");
  // The count stops at the first node beyond the limit: what follows is never read
  // (here it would not even be a node list), and the refusal is the limit's.
  {
    std::ofstream f(dir_ / "scenes" / "long.txt");
    for (int k = 0; k < 9; ++k) f << k << " 0 -1\n";
    f << std::string(1 << 20, 'x') << '\n';
  }
  const std::string long_file = open_node_file("long.txt");
  EXPECT_TRUE(contains(long_file, "long.txt' lists more than 8 nodes")) << long_file;
}

// plan_session runs on the RPC thread: it checks the message only and touches no
// file; the scene, its existence and its files are resolve_scene's (the session's thread).
TEST_F(ServerRequests, PlanningASessionReadsNoFiles) {
  capnp::MallocMessageBuilder mb;
  auto request = mb.initRoot<wire::OpenRequest>();
  request.getScene().setName("no_such_scene");
  request.setRateHz(500);
  request.setHeadless(true);
  request.initOverrides(1).set(0, "mls.neighbors=26");
  const OpenPlan plan = plan_session(request, options_);
  EXPECT_EQ(plan.kind, OpenPlan::SceneKind::name);
  EXPECT_EQ(plan.name, "no_such_scene");
  EXPECT_EQ(plan.sim.rate_hz, 500.0);
  EXPECT_TRUE(plan.sim.headless);
  ASSERT_EQ(plan.overrides.size(), 1u);
  EXPECT_EQ(plan.overrides[0].first, "mls.neighbors");
  try {
    resolve_scene(plan, options_);
    ADD_FAILURE() << "an unknown scene was resolved";
  } catch (const kj::Exception& e) {
    EXPECT_TRUE(contains(e.getDescription().cStr(), "unknown scene 'no_such_scene' (known: default)"))
        << e.getDescription().cStr();
  }
  // An inline scene naming a missing node file: planned, refused when resolved.
  auto inline_request = mb.initRoot<wire::OpenRequest>();
  auto d = inline_request.getScene().initInlineScene().initBody().initDistribution();
  d.setType(wire::DistributionType::NODE_FILE);
  d.setNodeFile("missing.txt");
  const OpenPlan inline_plan = plan_session(inline_request, options_);
  EXPECT_EQ(inline_plan.kind, OpenPlan::SceneKind::inline_scene);
  EXPECT_TRUE(contains(inline_plan.inline_json, "missing.txt")) << inline_plan.inline_json;
  EXPECT_THROW(resolve_scene(inline_plan, options_), kj::Exception);
  // What the RPC thread refuses by itself.
  auto bad = mb.initRoot<wire::OpenRequest>();
  bad.getScene().setName("../default");
  EXPECT_THROW(plan_session(bad, options_), kj::Exception);
  bad.getScene().setName("default");
  bad.setRateHz(-1);
  EXPECT_THROW(plan_session(bad, options_), kj::Exception);
  bad.setRateHz(0);
  bad.initOverrides(1).set(0, "no_equals_sign");
  EXPECT_THROW(plan_session(bad, options_), kj::Exception);
}

// Every mistake in an inline scene reaches the client as an RPC error naming the field
// (a fuzzer found bad UTF-8 escaping as a JSON library's exception).
TEST_F(ServerRequests, InlineSceneMistakesAreRpcErrorsNamingTheField) {
  EXPECT_NE(open_node_file("nodes\xe2x.txt").find("/body/distribution/node_file"), std::string::npos);
  EXPECT_NE(open_node_file("nodes\xe2x.txt").find("UTF-8"), std::string::npos);
  capnp::MallocMessageBuilder mb;
  auto request = mb.initRoot<wire::OpenRequest>();
  auto scene = request.getScene().initInlineScene();
  scene.initFixedRegions(1)[0].initSphere().setRadius(0.1);  // regions, but `fixed` (the faces) null
  try {
    session_scene(request, options_);
    FAIL() << "fixed regions without fixed faces were accepted";
  } catch (const kj::Exception& e) {
    EXPECT_NE(std::string(e.getDescription().cStr()).find("<rpc scene>: /fixed"), std::string::npos)
        << e.getDescription().cStr();
  }
}

TEST_F(ServerRequests, OverridesCannotPointANamedSceneElsewhere) {
  capnp::MallocMessageBuilder mb;
  auto request = mb.initRoot<wire::OpenRequest>();
  request.getScene().setName("default");
  auto o = request.initOverrides(2);
  o.set(0, "body.distribution.type=node_file");
  o.set(1, "body.distribution.node_file=/dev/zero");
  EXPECT_THROW(session_scene(request, options_), kj::Exception);
}

TEST_F(ServerRequests, CommandsOutOfRangeAreRefused) {
  EXPECT_NO_THROW(check_force(-10.0, 100.0));
  EXPECT_THROW(check_force(std::nan(""), 100.0), kj::Exception);
  EXPECT_THROW(check_force(100.5, 100.0), kj::Exception);
  EXPECT_THROW(check_step_count(0), kj::Exception);
  EXPECT_THROW(check_step_count(1000001), kj::Exception);
  EXPECT_THROW(check_subscriber_rate(-1.0), kj::Exception);
  EXPECT_NO_THROW(check_subscriber_rate(0.0));
  EXPECT_EQ(check_queued("setForce", 12), 12u);
  try {
    check_queued("setForce", 0);  // Simulation::enqueue found the queue full
    ADD_FAILURE() << "a full queue was not refused";
  } catch (const kj::Exception& e) {
    EXPECT_STREQ(e.getDescription().cStr(), "setForce: command queue full (4096 commands pending)");
  }
}

}  // namespace
}  // namespace palpate::server
