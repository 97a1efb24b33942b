// libFuzzer target: palpate::load_node_list (core/node_cloud.h), the "x y z"
// node-list reader. The input is written to a private temporary file (the reader
// takes a path). The contract: a NodeCloud of finite positions is returned or a
// std::runtime_error thrown naming the file and line.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "core/node_cloud.h"

namespace {

// One file per process, rewritten for every input, removed at exit.
struct TempFile {
  TempFile() {
    const char* dir = std::getenv("TMPDIR");
    path = std::string(dir && *dir ? dir : "/tmp") + "/palpate-node-list-fuzz-XXXXXX";
    const int fd = mkstemp(path.data());
    if (fd < 0) std::abort();
    close(fd);
  }
  ~TempFile() { unlink(path.c_str()); }
  std::string path;
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static TempFile file;
  std::FILE* f = std::fopen(file.path.c_str(), "wb");
  if (!f) std::abort();
  if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  try {
    const palpate::NodeCloud cloud = palpate::load_node_list(file.path);
    if (cloud.positions.cols() < 8 || !cloud.positions.allFinite()) std::abort();  // the promised result
  } catch (const std::runtime_error&) {
  }
  return 0;
}
