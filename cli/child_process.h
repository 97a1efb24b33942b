#pragma once
// Child processes for the benches and the tests (header only, POSIX): a program run to its
// end with what it printed (run_program), and palpate-server on a loopback port the system
// picks (ServerProcess: palpate-bench-server, -haptic, -frame-bytes and the end-to-end tests).
// Both on ChildProcess: fork, stdout (and stderr) piped back, exec, wait, stop.
#include <fcntl.h>
#include <limits.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

namespace palpate::cli {

// A program run as a child: argv[0] (a path) with argv; its stdout, and stderr if asked,
// piped to us (else inherited). It dies with the thread that started it (PR_SET_PDEATHSIG),
// so a test that aborts leaves no orphan.
class ChildProcess {
 public:
  struct Options {
    bool capture_stderr = false;
    int cpu = -1;               // >= 0: pinned to this CPU (and so every thread it starts)
    int stop_signal = SIGTERM;  // what the destructor sends it if it still runs
  };

  // Aborts when it cannot fork; a program that cannot be executed exits with status 127.
  ChildProcess(const std::vector<std::string>& argv, const Options& options) : stop_signal_(options.stop_signal) {
    int out[2], err[2] = {-1, -1};
    if (pipe2(out, O_CLOEXEC) != 0 || (options.capture_stderr && pipe2(err, O_CLOEXEC) != 0)) std::abort();
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    pid_ = fork();
    if (pid_ < 0) std::abort();
    if (pid_ == 0) {
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (options.cpu >= 0) {
        cpu_set_t set;
        CPU_ZERO(&set);
        CPU_SET(options.cpu, &set);
        if (sched_setaffinity(0, sizeof set, &set) != 0) {
          std::fprintf(stderr, "cannot pin %s to CPU %d\n", args[0], options.cpu);
          _exit(127);
        }
      }
      dup2(out[1], STDOUT_FILENO);
      if (err[1] >= 0) dup2(err[1], STDERR_FILENO);
      execv(args[0], args.data());
      _exit(127);
    }
    close(out[1]);
    stdout_fd_ = out[0];
    if (err[1] >= 0) {
      close(err[1]);
      stderr_fd_ = err[0];
    }
  }
  // Sends the stop signal to a child that still runs and reaps it.
  ~ChildProcess() {
    if (pid_ > 0) {
      kill(pid_, stop_signal_);
      waitpid(pid_, nullptr, 0);
    }
    for (int fd : {stdout_fd_, stderr_fd_})
      if (fd >= 0) close(fd);
  }
  ChildProcess(const ChildProcess&) = delete;
  ChildProcess& operator=(const ChildProcess&) = delete;

  pid_t pid() const { return pid_; }  // -1 once reaped
  int stdout_fd() const { return stdout_fd_; }
  int stderr_fd() const { return stderr_fd_; }  // -1 unless captured
  bool alive() const { return pid_ > 0 && kill(pid_, 0) == 0 && waitpid(pid_, nullptr, WNOHANG) == 0; }

  // Waits until it exits, at most `timeout`: its exit status (128 + the signal if a signal
  // ended it), or -1 if it still runs.
  int wait(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      int status = 0;
      if (pid_ > 0 && waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      if (pid_ <= 0 || std::chrono::steady_clock::now() >= deadline) return -1;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  // SIGTERM, then wait(timeout).
  int terminate(std::chrono::milliseconds timeout) {
    if (pid_ > 0) kill(pid_, SIGTERM);
    return wait(timeout);
  }
  // SIGKILL and reap.
  void kill_now() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }

  // A numeric field of /proc/PID/status ("VmRSS:", "Threads:"), -1 if absent.
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

 private:
  pid_t pid_ = -1;
  int stdout_fd_ = -1, stderr_fd_ = -1;
  int stop_signal_;
};

// A program run to its end: its exit status (128 + the signal if a signal ended it; -1 if it
// was killed at the timeout), stdout and stderr.
struct ProgramResult {
  int status = -1;
  std::string out, err;
};

inline ProgramResult run_program(const std::vector<std::string>& argv, std::chrono::milliseconds timeout) {
  ChildProcess child(argv, {.capture_stderr = true, .stop_signal = SIGKILL});
  ProgramResult r;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  bool open[2] = {true, true};
  const int fds[2] = {child.stdout_fd(), child.stderr_fd()};
  std::string* text[2] = {&r.out, &r.err};
  while ((open[0] || open[1]) && std::chrono::steady_clock::now() < deadline) {
    pollfd p[2] = {{fds[0], POLLIN, 0}, {fds[1], POLLIN, 0}};
    if (poll(p, 2, 100) <= 0) continue;
    for (int k = 0; k < 2; ++k) {
      if (!open[k] || !(p[k].revents & (POLLIN | POLLHUP))) continue;
      char buf[4096];
      const ssize_t n = read(fds[k], buf, sizeof buf);
      if (n > 0) text[k]->append(buf, static_cast<size_t>(n));
      else open[k] = false;
    }
  }
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
  r.status = child.wait(std::max(left, std::chrono::milliseconds(0)));
  if (r.status == -1) child.kill_now();  // still running at the timeout
  return r;
}

// `given` if not empty, else the program `name` in the folder of this one (/proc/self/exe,
// else argv0's folder): palpate-server beside the bench that starts it.
inline std::string program_path(const std::string& given, const std::string& name, const char* argv0) {
  if (!given.empty()) return given;
  char self[PATH_MAX] = {};
  const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
  const std::filesystem::path here(n > 0 ? std::string(self, static_cast<size_t>(n)) : std::string(argv0));
  return (here.parent_path() / name).string();
}

// palpate-server as a child process: `path --listen 127.0.0.1:0 ARGS...` (a later option
// wins), its stderr inherited. Ready once its "palpate-server listening on HOST:PORT" line
// arrived on stdout and, when ARGS hold --http, its "web on http[s]://HOST:PORT/" line, both
// within Options::wait (the server validates and builds its default scene before it
// listens: seconds for the finer study scenes). The stop signal at the end: SIGTERM unless
// the options say otherwise.
class ServerProcess {
 public:
  struct Options {
    std::chrono::milliseconds wait = std::chrono::seconds(20);
    int cpu = -1;  // >= 0: the server (every thread it will start) pinned to this CPU
    int stop_signal = SIGTERM;
  };

  ServerProcess(const std::string& path, const std::vector<std::string>& args, const Options& options)
      : path_(path), child_(command(path, args), {.cpu = options.cpu, .stop_signal = options.stop_signal}) {
    const bool http = std::find(args.begin(), args.end(), "--http") != args.end();
    const auto deadline = std::chrono::steady_clock::now() + options.wait;
    for (;;) {
      const auto listening = output_.find("listening on "), web = output_.find("web on ");
      if (listening != std::string::npos && output_.find('\n', listening) != std::string::npos &&
          (!http || (web != std::string::npos && output_.find('\n', web) != std::string::npos))) {
        address_ = output_.substr(listening + 13, output_.find_first_of(" \r\n", listening + 13) - listening - 13);
        port_ = port_of(address_);
        if (http) {
          const auto scheme = output_.find("://", web);
          if (scheme != std::string::npos)
            web_port_ = port_of(output_.substr(scheme + 3, output_.find_first_of("/ \r\n", scheme + 3) - scheme - 3));
        }
        ready_ = port_ > 0 && (!http || web_port_ > 0);
        break;
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) break;
      pollfd p{child_.stdout_fd(), POLLIN, 0};
      if (poll(&p, 1, static_cast<int>(std::min<long long>(left.count(), 100))) <= 0) continue;
      char buf[256];
      const ssize_t n = read(child_.stdout_fd(), buf, sizeof buf);
      if (n <= 0) break;  // it closed its stdout: it exited
      output_.append(buf, static_cast<size_t>(n));
    }
    if (!ready_) address_.clear();
    started_ = std::chrono::steady_clock::now();
  }

  bool ready() const { return ready_; }
  // For a program that cannot go on without its server: unless ready(), prints
  // "PROGRAM: the server did not start (PATH)" and exits with status 1.
  void exit_unless_ready(const char* program) const {
    if (ready_) return;
    std::fprintf(stderr, "%s: the server did not start (%s)\n", program, path_.c_str());
    std::exit(1);
  }
  const std::string& output() const { return output_; }  // its stdout until ready (or not)
  const std::string& address() const { return address_; }  // HOST:PORT it listens on ("" unless ready)
  int port() const { return port_; }
  int web_port() const { return web_port_; }  // with --http
  std::chrono::steady_clock::time_point started() const { return started_; }  // when it was ready

  pid_t pid() const { return child_.pid(); }
  bool alive() const { return child_.alive(); }
  int terminate(std::chrono::milliseconds timeout) { return child_.terminate(timeout); }  // ChildProcess::terminate
  long rss_kb() const { return child_.status_field("VmRSS:"); }
  long threads() const { return child_.status_field("Threads:"); }

 private:
  static std::vector<std::string> command(const std::string& path, const std::vector<std::string>& args) {
    std::vector<std::string> argv = {path, "--listen", "127.0.0.1:0"};
    argv.insert(argv.end(), args.begin(), args.end());
    return argv;
  }
  static int port_of(const std::string& host_port) {
    const auto colon = host_port.rfind(':');
    if (colon == std::string::npos) return 0;
    return std::atoi(host_port.c_str() + colon + 1);
  }

  std::string path_;
  ChildProcess child_;
  std::string output_, address_;
  int port_ = 0, web_port_ = 0;
  bool ready_ = false;
  std::chrono::steady_clock::time_point started_;
};

}  // namespace palpate::cli
