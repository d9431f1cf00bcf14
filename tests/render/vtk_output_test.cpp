// tests/render/vtk_output_test.cpp — frames written by VtkSeriesWriter read
// back with VTK's own reader, the .pvd with VTK's XML parser.
#include <gtest/gtest.h>

#if defined(MARBLES_HAVE_VTK)
#include <vtkCellData.h>
#include <vtkDataArray.h>
#include <vtkFieldData.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkStringArray.h>
#include <vtkXMLDataElement.h>
#include <vtkXMLDataParser.h>
#include <vtkXMLPolyDataReader.h>
#endif

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "render/vtk_output.hpp"

namespace fs = std::filesystem;
using namespace marbles;
using namespace marbles::render;

namespace {

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::path(MARBLES_BINARY_DIR) / "test-output" / "render" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

Snapshot make_snapshot(std::size_t n, double time, std::uint64_t step) {
  Snapshot s;
  s.time = time;
  s.step = step;
  for (std::size_t i = 0; i < n; ++i) {
    const real k = real(i);
    s.position.emplace_back(k, 2 * k, real(time) + k);
    s.velocity.emplace_back(3, 4 * k, 0);
    s.angular_velocity.emplace_back(0, 0, -k);
    s.radius.push_back(real(0.5) + k / 100);
    s.id.push_back(std::uint32_t(100 + i));
    s.material.push_back(std::uint32_t(i % 3));
  }
  return s;
}

}  // namespace

#if defined(MARBLES_HAVE_VTK)
// VTK's own reader (an independent oracle, where libvtk9-dev is installed)
// reads every frame, array and field-data entry we write.
TEST(VtkOutput, FramesReadBackWithVtkReader) {
  const fs::path dir = fresh_dir("vtk_frames");
  VtkSeriesWriter writer(dir, parse_point_fields({"radius", "velocity", "angular_velocity", "id", "material", "speed"}));
  for (int f = 0; f < 3; ++f) writer.write(make_snapshot(5 + f, 0.1 * f, 10 * f));
  EXPECT_EQ(writer.frames(), 3u);

  for (int f = 0; f < 3; ++f) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06d.vtp", f);
    const fs::path path = dir / "frames" / name;
    ASSERT_TRUE(fs::exists(path)) << path;
    // Binary (appended raw) and compressed.
    std::ifstream in(path, std::ios::binary);
    std::string head(512, '\0');
    in.read(head.data(), 512);
    EXPECT_NE(head.find("compressor=\"vtkZLibDataCompressor\""), std::string::npos);
    EXPECT_NE(head.find("format=\"appended\""), std::string::npos);

    vtkNew<vtkXMLPolyDataReader> reader;
    reader->SetFileName(path.c_str());
    reader->Update();
    vtkPolyData* poly = reader->GetOutput();
    const Snapshot want = make_snapshot(5 + f, 0.1 * f, 10 * f);
    const vtkIdType n = vtkIdType(want.size());
    ASSERT_EQ(poly->GetNumberOfPoints(), n);
    EXPECT_EQ(poly->GetNumberOfVerts(), n);
    vtkPointData* pd = poly->GetPointData();
    struct Expect {
      const char* name;
      int components;
    };
    for (Expect e : {Expect{"radius", 1}, Expect{"velocity", 3}, Expect{"angular_velocity", 3}, Expect{"id", 1},
                     Expect{"material", 1}, Expect{"speed", 1}}) {
      vtkDataArray* a = pd->GetArray(e.name);
      ASSERT_NE(a, nullptr) << e.name;
      EXPECT_EQ(a->GetNumberOfComponents(), e.components) << e.name;
      EXPECT_EQ(a->GetNumberOfTuples(), n) << e.name;
    }
    for (vtkIdType i = 0; i < n; ++i) {
      double p[3];
      poly->GetPoint(i, p);
      EXPECT_EQ(p[0], want.position[i].x);
      EXPECT_EQ(p[2], want.position[i].z);
      EXPECT_EQ(pd->GetArray("radius")->GetComponent(i, 0), want.radius[i]);
      EXPECT_EQ(pd->GetArray("velocity")->GetComponent(i, 1), want.velocity[i].y);
      EXPECT_EQ(pd->GetArray("angular_velocity")->GetComponent(i, 2), want.angular_velocity[i].z);
      EXPECT_EQ(pd->GetArray("id")->GetComponent(i, 0), want.id[i]);
      EXPECT_EQ(pd->GetArray("material")->GetComponent(i, 0), want.material[i]);
      EXPECT_NEAR(pd->GetArray("speed")->GetComponent(i, 0), length(want.velocity[i]), 1e-5);
    }
    EXPECT_EQ(pd->GetArray("id")->GetDataType(), VTK_UNSIGNED_INT);
    EXPECT_DOUBLE_EQ(poly->GetFieldData()->GetArray("TimeValue")->GetComponent(0, 0), 0.1 * f);
  }

  // The .pvd, through VTK's XML parser.
  vtkNew<vtkXMLDataParser> parser;
  const std::string pvd = (dir / "series.pvd").string();
  parser->SetFileName(pvd.c_str());
  ASSERT_EQ(parser->Parse(), 1);
  vtkXMLDataElement* root = parser->GetRootElement();
  ASSERT_STREQ(root->GetName(), "VTKFile");
  EXPECT_STREQ(root->GetAttribute("type"), "Collection");
  vtkXMLDataElement* collection = root->FindNestedElementWithName("Collection");
  ASSERT_NE(collection, nullptr);
  ASSERT_EQ(collection->GetNumberOfNestedElements(), 3);
  for (int f = 0; f < 3; ++f) {
    vtkXMLDataElement* ds = collection->GetNestedElement(f);
    EXPECT_STREQ(ds->GetName(), "DataSet");
    double t = -1;
    ds->GetScalarAttribute("timestep", t);
    EXPECT_DOUBLE_EQ(t, 0.1 * f);
    char name[40];
    std::snprintf(name, sizeof name, "frames/frame_%06d.vtp", f);
    EXPECT_STREQ(ds->GetAttribute("file"), name);
  }

  // No temporary files anywhere.
  for (const auto& e : fs::recursive_directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

TEST(VtkOutput, FieldDataCarriesMaterialNamesUnitsAndProducer) {
  const fs::path dir = fresh_dir("vtk_field_data");
  VtkSeriesWriter writer(dir, parse_point_fields({"radius"}), FrameMetadata{{"glass", "steel & co"}, "marbles test"});
  const fs::path frame = writer.write(make_snapshot(4, 0.25, 7));
  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(frame.c_str());
  reader->Update();
  ASSERT_EQ(reader->GetErrorCode(), 0);
  vtkFieldData* fd = reader->GetOutput()->GetFieldData();
  auto strings = [&](const char* name) {
    std::vector<std::string> out;
    if (auto* a = vtkStringArray::SafeDownCast(fd->GetAbstractArray(name)))
      for (vtkIdType i = 0; i < a->GetNumberOfValues(); ++i) out.push_back(a->GetValue(i));
    return out;
  };
  EXPECT_EQ(strings("material_names"), (std::vector<std::string>{"glass", "steel & co"}));
  EXPECT_EQ(strings("producer"), (std::vector<std::string>{"marbles test"}));
  EXPECT_EQ(strings("units").front(), "length m");
  ASSERT_NE(fd->GetArray("TimeValue"), nullptr);
  EXPECT_EQ(fd->GetArray("TimeValue")->GetComponent(0, 0), 0.25);
}

// VTK's reader sees the walls as polygons with their cell data.
TEST(VtkOutput, WallSurfacesReadBackWithVtkReader) {
  const fs::path dir = fresh_dir("vtk_walls");
  Walls walls;
  walls.planes.push_back({Vec3(0, 0, 0), Vec3(0, 0, 1), 1, Vec3()});
  walls.boxes.push_back({Vec3(0, 0, 0), Vec3(1, 1, 1), 0, Vec3()});
  WallSeriesWriter writer(dir, Vec3(0, 0, 0), Vec3(1, 1, 1));
  const fs::path file = writer.write(walls, 0.5, 10);
  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(file.c_str());
  reader->Update();
  ASSERT_EQ(reader->GetErrorCode(), 0);
  vtkPolyData* poly = reader->GetOutput();
  EXPECT_EQ(poly->GetNumberOfPolys(), 7);  // a square and six faces
  EXPECT_EQ(poly->GetNumberOfPoints(), 28);
  ASSERT_NE(poly->GetCellData()->GetArray("material"), nullptr);
  EXPECT_EQ(poly->GetCellData()->GetArray("material")->GetComponent(0, 0), 1.0);
  EXPECT_EQ(poly->GetCellData()->GetArray("wall")->GetComponent(6, 0), 1.0);
}
#endif

// Large arrays span many 32 KiB compression blocks; the reader gets every value back.
TEST(VtkOutput, ManyBlocksRoundTrip) {
  const fs::path dir = fresh_dir("vtk_blocks");
  VtkSeriesWriter writer(dir, parse_point_fields({"radius", "velocity", "id"}));
  const Snapshot a = make_snapshot(20000, 1.5, 3);  // 240 KB of positions: 8 blocks
  const Snapshot b = read_vtp(writer.write(a));
  EXPECT_EQ(b.position, a.position);
  EXPECT_EQ(b.velocity, a.velocity);
  EXPECT_EQ(b.radius, a.radius);
  EXPECT_EQ(b.id, a.id);
  EXPECT_EQ(b.time, 1.5);
  // A damaged file is an error naming it, never a crash or garbage.
  const fs::path frame = dir / "frames" / "frame_000000.vtp";
  std::string bytes;
  {
    std::ifstream in(frame, std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    bytes = text.str();
  }
  for (const std::size_t keep : {bytes.size() / 2, bytes.size() - 100}) {
    const fs::path cut = dir / ("cut_" + std::to_string(keep) + ".vtp");
    std::ofstream(cut, std::ios::binary) << bytes.substr(0, keep);
    EXPECT_THROW(read_vtp(cut), InputError) << keep;
  }
}

// An independent reader (Python's xml, zlib and struct; where python3 is
// installed) decodes our frames to the values written.
TEST(VtkOutput, PythonReadsTheFrames) {
  if (std::system("python3 -c 'import zlib' >/dev/null 2>&1") != 0) GTEST_SKIP() << "skipped: no python3";
  const fs::path dir = fresh_dir("vtk_python");
  VtkSeriesWriter writer(dir, parse_point_fields({"radius", "velocity"}), FrameMetadata{{"glass"}, "marbles"});
  const Snapshot a = make_snapshot(9000, 0.5, 1);
  const fs::path frame = writer.write(a);
  const fs::path script = dir / "read.py";
  std::ofstream(script) << R"PY(import struct, sys, zlib, re
data = open(sys.argv[1], 'rb').read()
head, _, tail = data.partition(b'<AppendedData encoding="raw">')
raw = tail[tail.index(b'_') + 1:]
def array(offset):
    blocks, size, last = struct.unpack_from('<3Q', raw, offset)
    sizes = struct.unpack_from('<%dQ' % blocks, raw, offset + 24)
    at, out = offset + 24 + 8 * blocks, b''
    for s in sizes:
        out += zlib.decompress(raw[at:at + s]); at += s
    return out
arrays = dict(re.findall(rb'Name="(\w+)"[^>]*offset="(\d+)"', head))
points = struct.unpack('<%df' % (3 * int(sys.argv[2])), array(int(arrays[b'Points'])))
radius = struct.unpack('<%df' % int(sys.argv[2]), array(int(arrays[b'radius'])))
names = array(int(arrays[b'material_names'])).split(b'\0')[:-1]
print(points[3], points[4], points[5], points[-1], radius[0], radius[-1], names[0].decode())
)PY";
  const fs::path out = dir / "out.txt";
  ASSERT_EQ(std::system(("python3 " + script.string() + " " + frame.string() + " " + std::to_string(a.size()) + " >" +
                         out.string())
                            .c_str()),
            0);
  std::ifstream in(out);
  double x1, y1, z1, z_last, r0, r_last;
  std::string material;
  in >> x1 >> y1 >> z1 >> z_last >> r0 >> r_last >> material;
  EXPECT_EQ(x1, a.position[1].x);
  EXPECT_EQ(y1, a.position[1].y);
  EXPECT_EQ(z1, a.position[1].z);
  EXPECT_EQ(z_last, a.position.back().z);
  EXPECT_EQ(r0, a.radius[0]);
  EXPECT_EQ(r_last, a.radius.back());
  EXPECT_EQ(material, "glass");
}

TEST(VtkOutput, ReaderRoundTripsIntoASnapshot) {
  const fs::path dir = fresh_dir("vtk_roundtrip");
  VtkSeriesWriter writer(dir, parse_point_fields({"radius", "velocity", "angular_velocity", "id", "material"}));
  const Snapshot a = make_snapshot(7, 0.5, 42);
  writer.write(a);
  writer.write(make_snapshot(7, 0.75, 43));
  const auto entries = read_pvd(writer.pvd_path());
  ASSERT_EQ(entries.size(), 2u);
  EXPECT_EQ(entries[1].time, 0.75);
  const Snapshot b = read_vtp(entries[0].path);
  EXPECT_EQ(b.time, 0.5);
  EXPECT_EQ(b.step, 42u);
  EXPECT_EQ(b.position, a.position);
  EXPECT_EQ(b.velocity, a.velocity);
  EXPECT_EQ(b.angular_velocity, a.angular_velocity);
  EXPECT_EQ(b.radius, a.radius);
  EXPECT_EQ(b.id, a.id);
  EXPECT_EQ(b.material, a.material);
}

TEST(VtkOutput, OnlyTheAskedFieldsAndClearErrors) {
  const fs::path dir = fresh_dir("vtk_fields");
  VtkSeriesWriter writer(dir, {PointField::radius});
  const fs::path frame = writer.write(make_snapshot(3, 0, 0));
  const Snapshot b = read_vtp(frame);
  EXPECT_EQ(b.radius.size(), 3u);
  EXPECT_TRUE(b.velocity.empty());
  EXPECT_TRUE(b.id.empty());

  Snapshot bad = make_snapshot(3, 0, 0);
  bad.radius.pop_back();
  EXPECT_THROW(writer.write(bad), RuntimeFailure);
  EXPECT_THROW(read_vtp(dir / "nope.vtp"), InputError);

  // An empty snapshot is a valid (empty) frame.
  const Snapshot empty = read_vtp(writer.write(Snapshot{}));
  EXPECT_EQ(empty.size(), 0u);
}
