// tests/core/files_test.cpp — core/files.hpp's copy_plain_file: the bytes and
// permission bits of the source, and the error that stopped a copy as it is
// (a full disk is "No space left on device", not "Input/output error").
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include "core/files.hpp"

namespace marbles {
namespace {

namespace fs = std::filesystem;

std::string slurp(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

struct Scratch {
  fs::path dir = fs::path(::testing::TempDir()) / ("marbles_files_" + std::to_string(getpid()));
  Scratch() { fs::create_directories(dir); }
  ~Scratch() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};

// Random bytes, longer than the copy's buffer and not a multiple of it.
std::string random_bytes(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::string bytes(n, '\0');
  for (char& c : bytes) c = static_cast<char>(rng());
  return bytes;
}

TEST(CopyPlainFile, CopiesTheBytesAndPermissionsOverAnEarlierFile) {
  const Scratch s;
  for (const std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{65536}, std::size_t{200003}}) {
    const std::string bytes = random_bytes(n, static_cast<unsigned>(n));
    std::ofstream(s.dir / "from", std::ios::binary) << bytes;
    ::chmod((s.dir / "from").c_str(), 0640);
    std::ofstream(s.dir / "to", std::ios::binary) << random_bytes(300000, 7);  // longer: replaced, not overlaid
    std::error_code ec;
    copy_plain_file(s.dir / "from", s.dir / "to", ec);
    ASSERT_FALSE(ec) << ec.message();
    EXPECT_EQ(slurp(s.dir / "to"), bytes) << n;
    struct stat st {};
    ASSERT_EQ(::stat((s.dir / "to").c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 07777, 0640u) << "an earlier file takes the source's bits";
    fs::remove(s.dir / "to");
    const mode_t mask = ::umask(077);  // a new file too, whatever the umask
    copy_plain_file(s.dir / "from", s.dir / "to", ec);
    ::umask(mask);
    ASSERT_FALSE(ec) << ec.message();
    ASSERT_EQ(::stat((s.dir / "to").c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 07777, 0640u);
  }
}

TEST(CopyPlainFile, SaysWhyItFailed) {
  const Scratch s;
  std::error_code ec;
  copy_plain_file(s.dir / "none", s.dir / "to", ec);
  EXPECT_EQ(ec, std::errc::no_such_file_or_directory) << ec.message();
  EXPECT_FALSE(fs::exists(s.dir / "to"));
  std::ofstream(s.dir / "from", std::ios::binary) << random_bytes(100000, 3);
  copy_plain_file(s.dir / "from", s.dir / "no_folder" / "to", ec);
  EXPECT_EQ(ec, std::errc::no_such_file_or_directory) << ec.message();
  // A pipe where the file should be: refused at once, not waited on.
  ASSERT_EQ(::mkfifo((s.dir / "pipe").c_str(), 0600), 0);
  copy_plain_file(s.dir / "pipe", s.dir / "to", ec);
  EXPECT_EQ(ec, std::errc::invalid_argument) << ec.message();
  EXPECT_FALSE(fs::exists(s.dir / "to"));
  // A full disk: /dev/full takes no byte (ENOSPC), and is left in place.
  if (!fs::exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  copy_plain_file(s.dir / "from", "/dev/full", ec);
  EXPECT_EQ(ec, std::errc::no_space_on_device) << ec.message();
  EXPECT_EQ(ec.message(), std::error_code(ENOSPC, std::generic_category()).message());
  EXPECT_TRUE(fs::exists("/dev/full"));
}

}  // namespace
}  // namespace marbles
