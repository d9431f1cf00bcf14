// core/error.hpp — the two kinds of failure the program reports.
//
// InputError: a scene, CSV or command-line problem; it carries where it was
// found (file:line:column, and the dotted key) so the command line prints
// `scenes/x.yaml:12:5: materials.glass.restitution: must be ...` and exits 2.
// RuntimeFailure: something went wrong while running (I/O, a device error,
// numerical blow-up); the command line prints it and exits 1.
#pragma once

#include <stdexcept>
#include <string>

#include "core/format.hpp"

namespace marbles {

struct SourceLocation {
  std::string file;  // empty when the input did not come from a file
  int line = 0;      // 1-based; 0 = unknown
  int column = 0;    // 1-based; 0 = unknown
};

class InputError : public std::runtime_error {
 public:
  InputError(SourceLocation where, std::string key, std::string message)
      : std::runtime_error(format(where, key, message)),
        m_where(std::move(where)), m_key(std::move(key)), m_message(std::move(message)) {}

  const SourceLocation& where() const { return m_where; }
  const std::string& key() const { return m_key; }
  const std::string& message() const { return m_message; }

  static std::string format(const SourceLocation& where, const std::string& key, const std::string& message) {
    std::string out;
    if (!where.file.empty()) {
      out += printable_path(where.file);  // one line, whatever the file's name holds
      if (where.line > 0) {
        out += ':';
        out += std::to_string(where.line);
        if (where.column > 0) {
          out += ':';
          out += std::to_string(where.column);
        }
      }
      out += ": ";
    }
    if (!key.empty()) out += key + ": ";
    out += message;
    return out;
  }

 private:
  SourceLocation m_where;
  std::string m_key;
  std::string m_message;
};

class RuntimeFailure : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace marbles
