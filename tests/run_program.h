#pragma once
// Runs another program of the build to its end for a test: exit status, stdout, stderr.
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

namespace palpate::test {

// Another program run to its end: exit status (-1 if killed at the timeout), stdout, stderr.
struct ProgramResult {
  int status = -1;
  std::string out, err;
};

inline ProgramResult run_program(const std::vector<std::string>& args, std::chrono::seconds timeout) {
  int out[2], err[2];
  if (pipe(out) != 0 || pipe(err) != 0) std::abort();
  const pid_t pid = fork();
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    dup2(out[1], STDOUT_FILENO);
    dup2(err[1], STDERR_FILENO);
    for (int fd : {out[0], out[1], err[0], err[1]}) close(fd);
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(argv[0], argv.data());
    _exit(127);
  }
  close(out[1]);
  close(err[1]);
  ProgramResult r;
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  bool open[2] = {true, true};
  const int fds[2] = {out[0], err[0]};
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
  int status = 0;
  pid_t done = 0;
  while ((done = waitpid(pid, &status, WNOHANG)) == 0 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  if (done == pid) {
    r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  } else {
    kill(pid, SIGKILL);  // our child, still running at the timeout
    waitpid(pid, nullptr, 0);
  }
  close(out[0]);
  close(err[0]);
  return r;
}

}  // namespace palpate::test
