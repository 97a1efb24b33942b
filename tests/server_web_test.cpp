// The web listener's pure parts (server/web.h): which Origins may open WebSocket RPC
// sessions, and which file a URL names (never one outside the viewer's folder).
#include <gtest/gtest.h>

#include "server/web.h"

namespace {

using palpate::server::content_type_for;
using palpate::server::origin_allowed;
using palpate::server::static_file_for;

kj::Maybe<kj::StringPtr> some(const char* s) { return kj::StringPtr(s); }

TEST(WebOrigin, SameOriginAndListedOriginsOnly) {
  const std::vector<std::string> none;
  EXPECT_TRUE(origin_allowed(nullptr, some("127.0.0.1:8080"), none)) << "no Origin: not a browser page";
  EXPECT_TRUE(origin_allowed(some("http://127.0.0.1:8080"), some("127.0.0.1:8080"), none));
  EXPECT_TRUE(origin_allowed(some("https://viewer.lab:443"), some("viewer.lab:443"), none));
  EXPECT_FALSE(origin_allowed(some("http://127.0.0.1:8081"), some("127.0.0.1:8080"), none)) << "another port";
  EXPECT_FALSE(origin_allowed(some("http://evil.example"), some("127.0.0.1:8080"), none));
  EXPECT_FALSE(origin_allowed(some("http://127.0.0.1:8080.evil.example"), some("127.0.0.1:8080"), none));
  EXPECT_FALSE(origin_allowed(some("http://127.0.0.1:8080"), nullptr, none)) << "no Host to compare with";
  EXPECT_FALSE(origin_allowed(some("null"), some("127.0.0.1:8080"), none)) << "a sandboxed or file: page";
  const std::vector<std::string> listed = {"http://trainer.lab:9000"};
  EXPECT_TRUE(origin_allowed(some("http://trainer.lab:9000"), some("127.0.0.1:8080"), listed));
  EXPECT_FALSE(origin_allowed(some("http://trainer.lab:9001"), some("127.0.0.1:8080"), listed));
  EXPECT_TRUE(origin_allowed(some("http://anything"), some("127.0.0.1:8080"), {"*"}));
}

TEST(WebFiles, PlainNamesUnderTheRootOnly) {
  const std::filesystem::path root = "/srv/viewer";
  EXPECT_EQ(static_file_for(root, ""), root / "index.html");
  EXPECT_EQ(static_file_for(root, "/"), root / "index.html");
  EXPECT_EQ(static_file_for(root, "/?session=3"), root / "index.html");
  EXPECT_EQ(static_file_for(root, "/viewer.js"), root / "viewer.js");
  EXPECT_EQ(static_file_for(root, "/viewer.js?v=2#x"), root / "viewer.js");
  EXPECT_EQ(static_file_for(root, "/assets/a-b_c.1.png"), root / "assets" / "a-b_c.1.png");
  for (const char* bad : {"/..", "/../etc/passwd", "/a/../../b", "/./index.html", "//etc/passwd", "/a//b", "/a/",
                          "/%2e%2e/x", "/a b", "viewer.js", "/\\..\\x"})
    EXPECT_TRUE(static_file_for(root, bad).empty()) << bad;
  EXPECT_STREQ(content_type_for("index.html"), "text/html; charset=utf-8");
  EXPECT_STREQ(content_type_for("viewer.js"), "text/javascript; charset=utf-8");
  EXPECT_STREQ(content_type_for("viewer.js.map"), "application/json");
  EXPECT_STREQ(content_type_for("x.bin"), "application/octet-stream");
}

}  // namespace
