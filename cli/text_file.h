#pragma once
// The whole text of a file a program was given (a secret, a certificate, a key), or
// std::invalid_argument naming what it is, the file and the system's reason.
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>

namespace palpate::cli {

// `what` says what the file is for, e.g. "--tls-cert": "--tls-cert x.pem: cannot be read (No such file ...)".
inline std::string read_text_file(const std::filesystem::path& file, const std::string& what) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw std::invalid_argument(what + " " + file.string() + ": cannot be read (" + std::strerror(errno) + ")");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw std::invalid_argument(what + " " + file.string() + ": cannot be read");
  return text;
}

// `text` without the white space (spaces, tabs, line ends) around it.
inline std::string trim_white_space(const std::string& text) {
  const auto first = text.find_first_not_of(" \t\r\n");
  if (first == std::string::npos) return "";
  return text.substr(first, text.find_last_not_of(" \t\r\n") - first + 1);
}

}  // namespace palpate::cli
