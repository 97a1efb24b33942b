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
      session_config(request, options_);
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

TEST_F(ServerRequests, OverridesCannotPointANamedSceneElsewhere) {
  capnp::MallocMessageBuilder mb;
  auto request = mb.initRoot<wire::OpenRequest>();
  request.getScene().setName("default");
  auto o = request.initOverrides(2);
  o.set(0, "body.distribution.type=node_file");
  o.set(1, "body.distribution.node_file=/dev/zero");
  EXPECT_THROW(session_config(request, options_), kj::Exception);
}

TEST_F(ServerRequests, CommandsOutOfRangeAreRefused) {
  EXPECT_NO_THROW(check_force(-10.0, 100.0));
  EXPECT_THROW(check_force(std::nan(""), 100.0), kj::Exception);
  EXPECT_THROW(check_force(100.5, 100.0), kj::Exception);
  EXPECT_THROW(check_step_count(0), kj::Exception);
  EXPECT_THROW(check_step_count(1000001), kj::Exception);
  EXPECT_THROW(check_subscriber_rate(-1.0), kj::Exception);
  EXPECT_NO_THROW(check_subscriber_rate(0.0));
}

}  // namespace
}  // namespace palpate::server
