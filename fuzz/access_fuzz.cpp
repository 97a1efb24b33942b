// libFuzzer target: the server's access checks on what a stranger controls (server/access.h,
// docs/protocol.md "Security model").
//
// The input is split at its first zero byte, if any, into two strings a and b:
//   - a, as the text of an --access-token-file: parse_access_token either refuses it with
//     std::invalid_argument or returns a token of at least kMinAccessTokenChars characters,
//     none of them white space or a control character, found in the text;
//   - a and b as a presented and an expected token: tokens_equal(a, b) must be a == b
//     (the constant-time comparison against plain equality), and symmetric;
//   - the whole input as the bytes of a PalpateServer.attach() or authenticate() call's
//     parameters (the wire form a client sends), read under bounded ReaderOptions: a
//     malformed message is a kj::Exception, a readable one yields the token compared.
// Anything else (a crash, a wrong answer, another exception) is a bug.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <string_view>

#include <capnp/serialize.h>
#include <kj/array.h>
#include <kj/exception.h>

#include "protocol/palpate.capnp.h"
#include "server/access.h"

namespace {

using namespace palpate::server;

void check_token_file(const std::string& text) {
  std::string token;
  try {
    token = parse_access_token(text, "<fuzz>");
  } catch (const std::invalid_argument&) {
    return;  // refused, with a message
  }
  if (token.size() < kMinAccessTokenChars) std::abort();
  for (const char c : token)
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f) std::abort();
  if (text.find(token) == std::string::npos) std::abort();
}

void check_compare(std::string_view a, std::string_view b) {
  const bool equal = tokens_equal(a, b);
  if (equal != (a == b) || equal != tokens_equal(b, a)) std::abort();
}

void check_wire(const uint8_t* data, size_t size) {
  // Whole words only (what a transport hands the reader), at most 64 KiB.
  const size_t words = std::min<size_t>(size / sizeof(capnp::word), 8192);
  if (words == 0) return;
  kj::Array<capnp::word> buffer = kj::heapArray<capnp::word>(words);
  std::memcpy(buffer.begin(), data, words * sizeof(capnp::word));
  capnp::ReaderOptions options;
  options.traversalLimitInWords = 1 << 16;
  options.nestingLimit = 16;
  try {
    capnp::FlatArrayMessageReader message(buffer, options);
    const bool attach = size % 2 == 0;
    std::string presented;
    if (attach) {
      auto params = message.getRoot<palpate::wire::PalpateServer::AttachParams>();
      (void)params.getSessionId();
      presented = params.getControlToken();
    } else {
      presented = message.getRoot<palpate::wire::PalpateServer::AuthenticateParams>().getAccessToken();
    }
    check_compare(presented, "5f1c0e2a9b7d4c3e8a6f0b1d2c3e4f5a6b7c8d9e0f1a2b3c4d5e6f708192a3b4");
  } catch (const kj::Exception&) {
    // malformed: the connection would end with this error
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  const auto zero = input.find('\0');
  const std::string a = input.substr(0, zero);
  const std::string b = zero == std::string::npos ? std::string() : input.substr(zero + 1);
  check_token_file(a);
  check_compare(a, b);
  check_compare(a, a);
  check_wire(data, size);
  return 0;
}
