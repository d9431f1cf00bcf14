// render/vtk_output.cpp — see vtk_output.hpp.
#include "render/vtk_output.hpp"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>

#include "core/error.hpp"
#include "core/format.hpp"
#include "render/atomic_file.hpp"

#if defined(MARBLES_HAVE_VTK)
#include <vtkCellArray.h>
#include <vtkDataArray.h>
#include <vtkDoubleArray.h>
#include <vtkFieldData.h>
#include <vtkFloatArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkTypeInt32Array.h>
#include <vtkTypeInt64Array.h>
#include <vtkTypeUInt32Array.h>
#include <vtkTypeUInt64Array.h>
#include <vtkVariant.h>
#include <vtkXMLPolyDataReader.h>
#include <vtkXMLPolyDataWriter.h>
#endif

namespace marbles::render {

namespace fs = std::filesystem;

static_assert(sizeof(Vec3) == 3 * sizeof(real), "Vec3 must be three packed reals");

std::optional<PointField> parse_point_field(std::string_view name) {
  if (name == "radius") return PointField::radius;
  if (name == "velocity") return PointField::velocity;
  if (name == "angular_velocity") return PointField::angular_velocity;
  if (name == "id") return PointField::id;
  if (name == "material") return PointField::material;
  if (name == "speed") return PointField::speed;
  return std::nullopt;
}

const char* point_field_name(PointField f) {
  switch (f) {
    case PointField::radius: return "radius";
    case PointField::velocity: return "velocity";
    case PointField::angular_velocity: return "angular_velocity";
    case PointField::id: return "id";
    case PointField::material: return "material";
    case PointField::speed: return "speed";
  }
  return "?";
}

std::vector<PointField> parse_point_fields(const std::vector<std::string>& names) {
  std::vector<PointField> fields;
  for (const std::string& name : names) {
    const auto f = parse_point_field(name);
    if (!f)
      throw InputError({}, "output.fields",
                       "unknown field '" + name + "' (expected radius, velocity, angular_velocity, id, material, speed)");
    if (std::find(fields.begin(), fields.end(), *f) == fields.end()) fields.push_back(*f);
  }
  return fields;
}

namespace {

[[maybe_unused]] std::string pvd_text(const std::vector<std::pair<double, std::string>>& entries) {
  std::ostringstream out;
  out << "<?xml version=\"1.0\"?>\n"
         "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n"
         "  <Collection>\n";
  for (const auto& [t, file] : entries) {
    out << "    <DataSet timestep=\"" << time_text(t) << "\" group=\"\" part=\"0\" file=\"" << file << "\"/>\n";
  }
  out << "  </Collection>\n</VTKFile>\n";
  return out.str();
}

}  // namespace

std::vector<SeriesEntry> read_pvd(const fs::path& pvd_path) {
  std::ifstream in(pvd_path, std::ios::binary);
  if (!in) throw RuntimeFailure("cannot read " + pvd_path.string());
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();

  static const std::regex dataset(R"(<DataSet\b([^>]*)>)");
  static const std::regex attribute(R"re(([A-Za-z_]+)\s*=\s*(?:"([^"]*)"|'([^']*)'))re");
  std::vector<SeriesEntry> entries;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), dataset); it != std::sregex_iterator(); ++it) {
    const std::string attrs = (*it)[1].str();
    std::optional<double> time;
    std::string file;
    for (auto a = std::sregex_iterator(attrs.begin(), attrs.end(), attribute); a != std::sregex_iterator(); ++a) {
      const std::string key = (*a)[1].str();
      const std::string value = (*a)[2].matched ? (*a)[2].str() : (*a)[3].str();
      if (key == "timestep") {
        char* end = nullptr;
        const double t = std::strtod(value.c_str(), &end);
        if (end != value.c_str()) time = t;
      } else if (key == "file") {
        file = value;
      }
    }
    if (file.empty()) continue;
    const fs::path p(file);
    entries.push_back({time.value_or(double(entries.size())), p.is_absolute() ? p : pvd_path.parent_path() / p});
  }
  if (entries.empty()) throw RuntimeFailure(pvd_path.string() + " lists no frames");
  return entries;
}

namespace {

// frames/frame_NNNNNN.vtp, numbered in write order.
std::string frame_name(std::size_t index) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%06zu.vtp", index);
  return name;
}

}  // namespace

void VtkSeriesWriter::adopt(double time) { m_entries.emplace_back(time, "frames/" + frame_name(m_entries.size())); }

#if defined(MARBLES_HAVE_VTK)

bool vtk_available() { return true; }

namespace {

// vtkFloatArray or vtkDoubleArray, matching `real`.
using RealArray = std::conditional_t<sizeof(real) == sizeof(float), vtkFloatArray, vtkDoubleArray>;

template <typename Array, typename T>
vtkSmartPointer<Array> make_array(const char* name, int components, const T* data, std::size_t tuples) {
  auto a = vtkSmartPointer<Array>::New();
  a->SetName(name);
  a->SetNumberOfComponents(components);
  a->SetNumberOfTuples(vtkIdType(tuples));
  if (tuples) std::memcpy(a->GetPointer(0), data, tuples * components * sizeof(T));
  return a;
}

void check_length(const char* name, std::size_t have, std::size_t n) {
  if (have != n)
    throw RuntimeFailure(std::string("VTK output: field '") + name + "' has " + std::to_string(have) +
                         " values for " + std::to_string(n) + " spheres");
}

}  // namespace

VtkSeriesWriter::VtkSeriesWriter(fs::path dir, std::vector<PointField> fields)
    : m_dir(std::move(dir)), m_fields(std::move(fields)) {
  std::error_code ec;
  fs::create_directories(m_dir / "frames", ec);
  if (ec) throw RuntimeFailure("cannot create " + (m_dir / "frames").string() + ": " + ec.message());
}

fs::path VtkSeriesWriter::write(const Snapshot& s) {
  const std::size_t n = s.size();
  vtkNew<vtkPolyData> poly;

  vtkNew<vtkPoints> points;
  points->SetData(make_array<RealArray>("Points", 3, &s.position.data()->x, n));
  poly->SetPoints(points);

  // One vertex cell per sphere.
  vtkNew<vtkTypeInt64Array> offsets, connectivity;
  offsets->SetNumberOfTuples(vtkIdType(n + 1));
  connectivity->SetNumberOfTuples(vtkIdType(n));
  for (std::size_t i = 0; i < n; ++i) {
    offsets->SetValue(vtkIdType(i), vtkTypeInt64(i));
    connectivity->SetValue(vtkIdType(i), vtkTypeInt64(i));
  }
  offsets->SetValue(vtkIdType(n), vtkTypeInt64(n));
  vtkNew<vtkCellArray> verts;
  verts->SetData(offsets, connectivity);
  poly->SetVerts(verts);

  vtkPointData* pd = poly->GetPointData();
  for (PointField f : m_fields) {
    const char* name = point_field_name(f);
    switch (f) {
      case PointField::radius:
        check_length(name, s.radius.size(), n);
        pd->AddArray(make_array<RealArray>(name, 1, s.radius.data(), n));
        break;
      case PointField::velocity:
        check_length(name, s.velocity.size(), n);
        pd->AddArray(make_array<RealArray>(name, 3, &s.velocity.data()->x, n));
        break;
      case PointField::angular_velocity:
        check_length(name, s.angular_velocity.size(), n);
        pd->AddArray(make_array<RealArray>(name, 3, &s.angular_velocity.data()->x, n));
        break;
      case PointField::id:
        check_length(name, s.id.size(), n);
        pd->AddArray(make_array<vtkTypeUInt32Array>(name, 1, s.id.data(), n));
        break;
      case PointField::material:
        check_length(name, s.material.size(), n);
        pd->AddArray(make_array<vtkTypeUInt32Array>(name, 1, s.material.data(), n));
        break;
      case PointField::speed: {
        check_length("velocity (for speed)", s.velocity.size(), n);
        std::vector<real> speed(n);
        for (std::size_t i = 0; i < n; ++i) speed[i] = length(s.velocity[i]);
        pd->AddArray(make_array<RealArray>(name, 1, speed.data(), n));
        break;
      }
    }
  }
  if (!m_fields.empty() && m_fields.front() == PointField::radius) pd->SetActiveScalars("radius");

  vtkNew<vtkDoubleArray> time;
  time->SetName("TimeValue");
  time->InsertNextValue(s.time);
  poly->GetFieldData()->AddArray(time);
  vtkNew<vtkTypeUInt64Array> step;
  step->SetName("step");
  step->InsertNextValue(s.step);
  poly->GetFieldData()->AddArray(step);

  const std::string name = frame_name(m_entries.size());
  const fs::path final_path = m_dir / "frames" / name;
  const fs::path tmp = temp_path_beside(final_path);
  vtkNew<vtkXMLPolyDataWriter> writer;
  writer->SetFileName(tmp.c_str());
  writer->SetInputData(poly);
  writer->SetDataModeToAppended();
  writer->EncodeAppendedDataOff();
  writer->SetCompressorTypeToZLib();
  writer->SetHeaderTypeToUInt64();
  if (writer->Write() != 1) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw RuntimeFailure("cannot write " + final_path.string() + " (disk full or not writable?)");
  }
  commit_file(tmp, final_path, ends_with("</VTKFile>"));

  m_entries.emplace_back(s.time, "frames/" + name);
  write_file_atomic(pvd_path(), pvd_text(m_entries));
  return final_path;
}

namespace {

template <typename T>
void read_scalars(vtkDataArray* a, std::vector<T>& out, vtkIdType n) {
  if (!a || a->GetNumberOfComponents() != 1 || a->GetNumberOfTuples() != n) return;
  out.resize(std::size_t(n));
  for (vtkIdType i = 0; i < n; ++i) out[std::size_t(i)] = static_cast<T>(a->GetComponent(i, 0));
}

void read_vectors(vtkDataArray* a, std::vector<Vec3>& out, vtkIdType n) {
  if (!a || a->GetNumberOfComponents() != 3 || a->GetNumberOfTuples() != n) return;
  out.resize(std::size_t(n));
  for (vtkIdType i = 0; i < n; ++i) {
    double v[3];
    a->GetTuple(i, v);
    out[std::size_t(i)] = Vec3(real(v[0]), real(v[1]), real(v[2]));
  }
}

}  // namespace

Snapshot read_vtp(const fs::path& vtp_path) {
  if (!fs::exists(vtp_path)) throw RuntimeFailure("cannot read " + vtp_path.string() + ": no such file");
  vtkNew<vtkXMLPolyDataReader> reader;
  reader->SetFileName(vtp_path.c_str());
  reader->Update();
  vtkPolyData* poly = reader->GetOutput();
  if (reader->GetErrorCode() != 0 || !poly)
    throw RuntimeFailure("cannot read " + vtp_path.string() + ": not a valid VTK poly data file");
  Snapshot s;
  const vtkIdType n = poly->GetNumberOfPoints();
  s.position.resize(std::size_t(n));
  for (vtkIdType i = 0; i < n; ++i) {
    double p[3];
    poly->GetPoint(i, p);
    s.position[std::size_t(i)] = Vec3(real(p[0]), real(p[1]), real(p[2]));
  }
  vtkPointData* pd = poly->GetPointData();
  read_scalars(pd->GetArray("radius"), s.radius, n);
  read_vectors(pd->GetArray("velocity"), s.velocity, n);
  read_vectors(pd->GetArray("angular_velocity"), s.angular_velocity, n);
  read_scalars(pd->GetArray("id"), s.id, n);
  read_scalars(pd->GetArray("material"), s.material, n);
  if (vtkDataArray* t = poly->GetFieldData()->GetArray("TimeValue"); t && t->GetNumberOfTuples() > 0)
    s.time = t->GetComponent(0, 0);
  if (vtkAbstractArray* st = poly->GetFieldData()->GetAbstractArray("step"); st && st->GetNumberOfTuples() > 0)
    s.step = st->GetVariantValue(0).ToTypeUInt64();
  return s;
}

#else  // !MARBLES_HAVE_VTK

bool vtk_available() { return false; }

namespace {
const char* kNoVtk = "marbles was built without VTK (libvtk9-dev): no .vtp frames can be written or read";
}

VtkSeriesWriter::VtkSeriesWriter(fs::path dir, std::vector<PointField> fields)
    : m_dir(std::move(dir)), m_fields(std::move(fields)) {
  throw RuntimeFailure(kNoVtk);
}

fs::path VtkSeriesWriter::write(const Snapshot&) { throw RuntimeFailure(kNoVtk); }

Snapshot read_vtp(const fs::path&) { throw RuntimeFailure(kNoVtk); }

#endif

}  // namespace marbles::render
