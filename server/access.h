#pragma once
// Who may do what (docs/protocol.md, "Security model"): the secrets the server hands out
// and checks, and what one connection has used of its limits. RPC thread only, except
// the pure functions.
//
//   - a control token: 32 bytes from the operating system's random source (getrandom),
//     written as 64 hex digits; returned by openSession to the opener only; attach()
//     with it gives a control reference, without it a read-only view;
//   - a session id: a random non-zero 32-bit number, unique among the live sessions; it
//     names a session (for attach) and grants nothing but viewing;
//   - the access token (--access-token-file): the shared secret a connection presents to
//     PalpateServer.authenticate before anything but version() is served.
// Secrets are compared in constant time (tokens_equal) and never logged.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

namespace palpate::server {

// `bytes` bytes from getrandom(2), as 2 * bytes lowercase hex digits. Throws
// std::runtime_error when the system has no random source to give.
std::string random_hex(size_t bytes);

// A random number in [1, 2^32 - 1].
uint32_t random_session_id();

// Whether a and b are equal, in a time that depends on their lengths only (not on
// where they differ), so that a guesser learns nothing from how long a refusal takes.
bool tokens_equal(std::string_view a, std::string_view b);

// Bytes of a control token (kControlTokenBytes * 8 = 256 bits).
inline constexpr size_t kControlTokenBytes = 32;
// The shortest access token --access-token-file accepts, in characters: 32 hex digits
// carry 128 bits (`openssl rand -hex 32` writes 64).
inline constexpr size_t kMinAccessTokenChars = 32;

// The access token in `file`: its text without a trailing newline (and spaces around it).
// Throws std::invalid_argument naming the file and the reason when it cannot be read, is
// shorter than kMinAccessTokenChars, or holds white space or control characters inside.
std::string read_access_token(const std::filesystem::path& file);
// The same on the file's text (`file` names it in messages).
std::string parse_access_token(const std::string& text, const std::string& file);

// What one client connection (TCP or WebSocket) has used of its limits. Shared by the
// connection's bootstrap capabilities and the sessions it opened (which give their
// count back when they end, whichever connection holds them then).
struct ConnectionState {
  int sessions_open = 0;  // sessions this connection opened that are still live
  int wrong_tokens = 0;   // refused attach() and authenticate() tokens, unknown ids included
};

}  // namespace palpate::server
