#pragma once
// palpate-server for a test (cli::ServerProcess, cli/child_process.h): the build's server
// (PALPATE_SERVER_BIN) with the source tree's scenes (PALPATE_SOURCE_DIR, both from
// tests/CMakeLists.txt) and errors only, then `args` (a later option wins: e.g. --log-level
// info); killed (SIGKILL) at the end. A server that does not start within 20 s aborts the test
// program, naming what it printed.
#include <cstdio>
#include <cstdlib>
#include <string>
#include <utility>
#include <vector>

#include "cli/child_process.h"

namespace palpate::test {

class ServerProcess : public cli::ServerProcess {
 public:
  // With --http (the default arguments), the web port is read too.
  explicit ServerProcess(std::vector<std::string> args = {"--http", "127.0.0.1:0"})
      : cli::ServerProcess(PALPATE_SERVER_BIN, with_defaults(std::move(args)),
                           {.wait = std::chrono::seconds(20), .stop_signal = SIGKILL}) {
    if (!ready()) {
      std::fprintf(stderr, "server did not start: '%s'\n", output().c_str());
      std::abort();
    }
  }

 private:
  static std::vector<std::string> with_defaults(std::vector<std::string> args) {
    std::vector<std::string> all = {"--scene-dir", PALPATE_SOURCE_DIR "/scenes", "--log-level", "error"};
    all.insert(all.end(), std::make_move_iterator(args.begin()), std::make_move_iterator(args.end()));
    return all;
  }
};

}  // namespace palpate::test
