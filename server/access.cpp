#include "server/access.h"

#include "cli/text_file.h"

#include <sys/random.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace palpate::server {

namespace {

void fill_random(void* out, size_t bytes) {
  auto* p = static_cast<unsigned char*>(out);
  while (bytes > 0) {
    const ssize_t n = getrandom(p, bytes, 0);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw std::runtime_error(std::string("getrandom: ") + std::strerror(errno));
    }
    p += n;
    bytes -= static_cast<size_t>(n);
  }
}

}  // namespace

std::string random_hex(size_t bytes) {
  std::string raw(bytes, '\0');
  fill_random(raw.data(), bytes);
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string hex(2 * bytes, '0');
  for (size_t k = 0; k < bytes; ++k) {
    const auto b = static_cast<unsigned char>(raw[k]);
    hex[2 * k] = kDigits[b >> 4];
    hex[2 * k + 1] = kDigits[b & 15];
  }
  return hex;
}

uint32_t random_session_id() {
  uint32_t id = 0;
  while (id == 0) fill_random(&id, sizeof id);
  return id;
}

bool tokens_equal(std::string_view a, std::string_view b) {
  // Every byte of the longer one is read, whatever the first difference.
  const size_t n = std::max(a.size(), b.size());
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (size_t k = 0; k < n; ++k) {
    const unsigned char x = k < a.size() ? static_cast<unsigned char>(a[k]) : 0;
    const unsigned char y = k < b.size() ? static_cast<unsigned char>(b[k]) : 0;
    diff |= static_cast<unsigned char>(x ^ y);
  }
  // Read through a volatile so that the compiler cannot stop the loop at the first difference.
  volatile unsigned char result = diff;
  return result == 0;
}

std::string read_access_token(const std::filesystem::path& file) {
  return parse_access_token(cli::read_text_file(file, "--access-token-file"), file.string());
}

std::string parse_access_token(const std::string& text, const std::string& file) {
  const std::string token = cli::trim_white_space(text);
  for (const char c : token)
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f)
      throw std::invalid_argument(file + ": the access token holds white space or a control character; "
                                                  "write it on one line (e.g. openssl rand -hex 32 > FILE)");
  if (token.size() < kMinAccessTokenChars)
    throw std::invalid_argument(file + ": the access token has " + std::to_string(token.size()) +
                                " characters, fewer than " + std::to_string(kMinAccessTokenChars) +
                                " (e.g. openssl rand -hex 32 > FILE writes 64)");
  return token;
}

}  // namespace palpate::server
