// The server's secrets (server/access.h): random tokens and ids, the constant-time
// comparison, the access token file's rules.
#include <set>
#include <string>

#include <gtest/gtest.h>

#include "server/access.h"

namespace {

using namespace palpate::server;

TEST(Access, ControlTokensAreHexOfTheRightLengthAndNeverRepeat) {
  std::set<std::string> seen;
  for (int k = 0; k < 1000; ++k) {
    const std::string t = random_hex(kControlTokenBytes);
    ASSERT_EQ(t.size(), 2 * kControlTokenBytes);
    for (const char c : t) ASSERT_TRUE((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f')) << t;
    EXPECT_TRUE(seen.insert(t).second) << "repeated: " << t;
  }
  // Every hex digit turns up in every position across the sample (a source stuck at some
  // bits would leave digits out): 1000 samples miss a given digit at a given place with
  // probability (15/16)^1000 ~ 1e-28.
  for (size_t pos = 0; pos < 2 * kControlTokenBytes; ++pos) {
    std::set<char> digits;
    for (const auto& t : seen) digits.insert(t[pos]);
    EXPECT_EQ(digits.size(), 16u) << "position " << pos;
  }
}

TEST(Access, SessionIdsAreNonZeroAndSpread) {
  std::set<uint32_t> ids;
  uint32_t high_bits = 0;
  for (int k = 0; k < 1000; ++k) {
    const uint32_t id = random_session_id();
    EXPECT_NE(id, 0u);
    ids.insert(id);
    high_bits |= id;
  }
  EXPECT_GE(ids.size(), 999u);  // a collision among 1000 of 2^32 has probability ~1e-4
  EXPECT_EQ(high_bits, 0xffffffffu) << "some bit never set: not a 32-bit random number";
}

TEST(Access, TokensEqualIsEqualityWhateverTheLengths) {
  const std::string t = random_hex(kControlTokenBytes);
  EXPECT_TRUE(tokens_equal(t, t));
  EXPECT_TRUE(tokens_equal("", ""));
  EXPECT_FALSE(tokens_equal(t, ""));
  EXPECT_FALSE(tokens_equal("", t));
  EXPECT_FALSE(tokens_equal(t, t + "0"));
  EXPECT_FALSE(tokens_equal(t.substr(0, 63), t));
  for (size_t k = 0; k < t.size(); ++k) {
    std::string u = t;
    u[k] = u[k] == 'a' ? 'b' : 'a';
    EXPECT_FALSE(tokens_equal(t, u)) << "differs at " << k;
  }
  // A prefix padded with zero bytes is not the token (the padding of the shorter side).
  EXPECT_FALSE(tokens_equal(std::string("ab"), std::string("ab\0", 3)));
}

TEST(Access, AccessTokenFilesAreCheckedNamingTheFile) {
  EXPECT_EQ(parse_access_token("  0123456789abcdef0123456789abcdef\n", "f"), "0123456789abcdef0123456789abcdef");
  EXPECT_EQ(parse_access_token("0123456789abcdef0123456789abcdef\r\n", "f"), "0123456789abcdef0123456789abcdef");
  auto message = [](const std::string& text) {
    try {
      parse_access_token(text, "/etc/palpate/token");
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(message(""), "/etc/palpate/token: the access token has 0 characters, fewer than 32 (e.g. openssl rand "
                         "-hex 32 > FILE writes 64)");
  EXPECT_NE(message("0123456789abcdef").find("has 16 characters"), std::string::npos);
  EXPECT_NE(message("0123456789abcdef 0123456789abcdef").find("white space"), std::string::npos);
  EXPECT_NE(message("0123456789abcdef\n0123456789abcdef").find("white space"), std::string::npos);
  EXPECT_NE(message(std::string("0123456789abcdef\x01", 17) + "0123456789abcdef").find("control character"),
            std::string::npos);
  EXPECT_NE(message("x").find("/etc/palpate/token: "), std::string::npos);
  EXPECT_THROW(read_access_token("/nonexistent/palpate-token"), std::invalid_argument);
}

}  // namespace
