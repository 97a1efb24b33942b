#pragma once
// palpate-server as a child process of a benchmark (palpate-bench-server,
// palpate-bench-haptic), listening on 127.0.0.1:<a port the system picks>.
#include <limits.h>
#include <sched.h>
#include <signal.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

namespace palpate::bench {

// `path` if given, else the palpate-server executable next to this one.
inline std::string server_path(const std::string& path, const char* argv0) {
  if (!path.empty()) return path;
  char self[PATH_MAX] = {};
  const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
  return (std::filesystem::path(n > 0 ? std::string(self, static_cast<size_t>(n)) : std::string(argv0)).parent_path() /
          "palpate-server")
      .string();
}

class ServerProcess {
 public:
  // Starts `path --listen 127.0.0.1:0 ARGS...` and reads the address from its
  // "listening on ADDR:PORT" line. The server validates and builds its default scene
  // before it listens (seconds for the finer study scenes): waits up to 120 s, else
  // prints "PROGRAM: the server did not start (PATH)" and exits with status 1.
  // cpu >= 0 pins the server (every thread it will start) to that CPU.
  ServerProcess(const std::string& path, const std::vector<std::string>& args, const char* program, int cpu = -1) {
    int out[2];
    if (pipe(out) != 0) std::exit(1);
    std::vector<std::string> argv_text = {path, "--listen", "127.0.0.1:0"};
    argv_text.insert(argv_text.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : argv_text) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid = fork();
    if (pid == 0) {
      if (cpu >= 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(cpu, &set);
        if (sched_setaffinity(0, sizeof set, &set) != 0) {
          std::fprintf(stderr, "%s: cannot pin the server to CPU %d\n", program, cpu);
          _exit(127);
        }
      }
      dup2(out[1], STDOUT_FILENO);
      close(out[0]);
      close(out[1]);
      execv(path.c_str(), argv.data());
      _exit(127);
    }
    close(out[1]);
    std::string line;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
    while (line.find('\n') == std::string::npos && std::chrono::steady_clock::now() < deadline) {
      char buf[256];
      const ssize_t n = read(out[0], buf, sizeof buf);
      if (n <= 0) break;
      line.append(buf, static_cast<size_t>(n));
    }
    close(out[0]);
    const auto at = line.find("listening on ");
    if (at == std::string::npos) {
      std::fprintf(stderr, "%s: the server did not start (%s)\n", program, path.c_str());
      std::exit(1);
    }
    address = line.substr(at + 13);
    while (!address.empty() && (address.back() == '\n' || address.back() == '\r')) address.pop_back();
  }
  ~ServerProcess() {
    if (pid > 0) {
      kill(pid, SIGTERM);
      waitpid(pid, nullptr, 0);
    }
  }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  pid_t pid = -1;
  std::string address;
};

}  // namespace palpate::bench
