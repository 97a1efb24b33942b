#pragma once
// palpate-server as a child process of an end-to-end test: on a loopback port the
// system picks (--listen 127.0.0.1:0, the port read from its first stdout line).
// PALPATE_SERVER_BIN and PALPATE_SOURCE_DIR come from tests/CMakeLists.txt.
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace palpate::test {

class ServerProcess {
 public:
  // palpate-server --listen 127.0.0.1:0 --scene-dir scenes/ --log-level error, then
  // `args` (a later option wins: e.g. --log-level info). With --http (the default
  // arguments), the web port is read too.
  explicit ServerProcess(std::vector<std::string> args = {"--http", "127.0.0.1:0"}) {
    const bool http = std::find(args.begin(), args.end(), "--http") != args.end();
    std::vector<std::string> argv_text = {PALPATE_SERVER_BIN, "--listen",   "127.0.0.1:0", "--scene-dir",
                                          PALPATE_SOURCE_DIR "/scenes", "--log-level", "error"};
    argv_text.insert(argv_text.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : argv_text) argv.push_back(a.data());
    argv.push_back(nullptr);
    int out[2];
    if (pipe(out) != 0) std::abort();
    pid_ = fork();
    if (pid_ == 0) {
      prctl(PR_SET_PDEATHSIG, SIGKILL);  // no orphan server when the test aborts (e.g. a sanitizer report)
      dup2(out[1], STDOUT_FILENO);
      close(out[0]);
      close(out[1]);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(out[1]);
    // Readiness: the "listening on 127.0.0.1:PORT" and (--http) "web on
    // http://127.0.0.1:PORT/" lines (bounded wait).
    std::string line;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    fcntl(out[0], F_SETFL, O_NONBLOCK);
    const char* last_line_end = http ? "/\n" : "\n";
    while (line.find(last_line_end) == std::string::npos && std::chrono::steady_clock::now() < deadline) {
      char buf[256];
      const ssize_t n = read(out[0], buf, sizeof buf);
      if (n > 0) line.append(buf, static_cast<size_t>(n));
      else if (n == 0) break;
      else std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    stdout_fd_ = out[0];
    const auto first = line.substr(0, line.find('\n'));
    const auto colon = first.rfind(':');
    // "web on http://127.0.0.1:PORT/", or https:// with --tls-cert.
    const std::string web_prefix = line.find("web on https://") != std::string::npos ? "web on https://127.0.0.1:"
                                                                                      : "web on http://127.0.0.1:";
    const auto web = line.find(web_prefix);
    if (first.find("listening on") == std::string::npos || colon == std::string::npos ||
        (http && web == std::string::npos)) {
      std::fprintf(stderr, "server did not start: '%s'\n", line.c_str());
      std::abort();
    }
    port_ = std::stoi(first.substr(colon + 1));
    if (http) web_port_ = std::stoi(line.substr(web + web_prefix.size()));
    started_ = std::chrono::steady_clock::now();
  }
  ~ServerProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    close(stdout_fd_);
  }
  int port() const { return port_; }
  int web_port() const { return web_port_; }
  pid_t pid() const { return pid_; }
  // When its listening line arrived (steady clock).
  std::chrono::steady_clock::time_point started() const { return started_; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  bool alive() const { return kill(pid_, 0) == 0 && waitpid(pid_, nullptr, WNOHANG) == 0; }
  long rss_kb() const { return status_field("VmRSS:"); }
  long threads() const { return status_field("Threads:"); }
  // SIGTERM; the exit status, or -1 if it did not exit within the timeout.
  int terminate(std::chrono::milliseconds timeout) {
    kill(pid_, SIGTERM);
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return -1;
  }

 private:
  long status_field(const std::string& name) const {
    std::ifstream f("/proc/" + std::to_string(pid_) + "/status");
    std::string key;
    long value = -1;
    while (f >> key) {
      if (key == name) {
        f >> value;
        break;
      }
      std::getline(f, key);
    }
    return value;
  }

  pid_t pid_ = -1;
  int stdout_fd_ = -1;
  int port_ = 0;
  int web_port_ = 0;
  std::chrono::steady_clock::time_point started_;
};

}  // namespace palpate::test
