#include "io/vtk_export.h"

#include <cstdio>
#include <fstream>
#include <memory>

#include "common/error.h"

namespace hapco::io {
namespace {

struct FileCloser {
  void operator()(std::FILE* file) const { std::fclose(file); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

File OpenForWriting(const std::string& path) {
  File file(std::fopen(path.c_str(), "w"));
  if (!file) throw InputError("cannot write VTK file " + path);
  return file;
}

void WriteVectorArray(std::FILE* out, const char* name, const Eigen::VectorXd& values) {
  std::fprintf(out, "        <DataArray type=\"Float64\" Name=\"%s\" NumberOfComponents=\"3\" format=\"ascii\">\n", name);
  for (Eigen::Index i = 0; i < values.size(); i += 3) {
    std::fprintf(out, "          %.10g %.10g %.10g\n", values[i], values[i + 1], values[i + 2]);
  }
  std::fprintf(out, "        </DataArray>\n");
}

void Close(File file, const std::string& path) {
  if (std::ferror(file.get()) != 0) throw InputError("error while writing " + path);
  if (std::fclose(file.release()) != 0) throw InputError("error while closing " + path);
}

}  // namespace

void WriteBodyVtu(const std::string& path, const fem::Mesh& mesh,
                  const Eigen::VectorXd& displacement_m, const Eigen::VectorXd& nodal_force_n) {
  const int num_nodes = mesh.num_nodes();
  if (displacement_m.size() != 3 * num_nodes || nodal_force_n.size() != 3 * num_nodes) {
    throw InputError("VTK export: fields must have 3 x " + std::to_string(num_nodes) + " entries");
  }
  const int per_element = fem::NodesPerElement(mesh.order);
  const int vtk_type = mesh.order == fem::ElementOrder::kTet4 ? 10 : 24;
  File file = OpenForWriting(path);
  std::FILE* out = file.get();
  std::fprintf(out, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\">\n");
  std::fprintf(out, "  <UnstructuredGrid>\n    <Piece NumberOfPoints=\"%d\" NumberOfCells=\"%d\">\n", num_nodes,
               mesh.num_elements());
  std::fprintf(out, "      <PointData Vectors=\"displacement_m\">\n");
  WriteVectorArray(out, "displacement_m", displacement_m);
  WriteVectorArray(out, "contact_force_n", nodal_force_n);
  std::fprintf(out, "      </PointData>\n      <Points>\n");
  Eigen::VectorXd positions(3 * num_nodes);
  for (int node = 0; node < num_nodes; ++node) positions.segment<3>(3 * node) = mesh.nodes_m.row(node).transpose();
  WriteVectorArray(out, "reference_position_m", positions);
  std::fprintf(out, "      </Points>\n      <Cells>\n");
  std::fprintf(out, "        <DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n");
  for (int e = 0; e < mesh.num_elements(); ++e) {
    std::fprintf(out, "         ");
    for (int k = 0; k < per_element; ++k) std::fprintf(out, " %d", mesh.elements(e, k));
    std::fprintf(out, "\n");
  }
  std::fprintf(out, "        </DataArray>\n        <DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n");
  for (int e = 0; e < mesh.num_elements(); ++e) std::fprintf(out, "          %d\n", (e + 1) * per_element);
  std::fprintf(out, "        </DataArray>\n        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
  for (int e = 0; e < mesh.num_elements(); ++e) std::fprintf(out, "          %d\n", vtk_type);
  std::fprintf(out, "        </DataArray>\n      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
  Close(std::move(file), path);
}

void WriteContactsVtu(const std::string& path, const std::vector<ContactPointRecord>& contacts) {
  const int count = static_cast<int>(contacts.size());
  File file = OpenForWriting(path);
  std::FILE* out = file.get();
  std::fprintf(out, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\">\n");
  std::fprintf(out, "  <UnstructuredGrid>\n    <Piece NumberOfPoints=\"%d\" NumberOfCells=\"%d\">\n", count, count);
  std::fprintf(out, "      <PointData Vectors=\"force_n\" Scalars=\"state\">\n");
  Eigen::VectorXd normals(3 * count), forces(3 * count), positions(3 * count);
  for (int i = 0; i < count; ++i) {
    normals.segment<3>(3 * i) = contacts[static_cast<std::size_t>(i)].normal;
    forces.segment<3>(3 * i) = contacts[static_cast<std::size_t>(i)].force_n;
    positions.segment<3>(3 * i) = contacts[static_cast<std::size_t>(i)].position_m;
  }
  WriteVectorArray(out, "normal", normals);
  WriteVectorArray(out, "force_n", forces);
  std::fprintf(out, "        <DataArray type=\"Int32\" Name=\"state\" format=\"ascii\">\n");
  for (const auto& contact : contacts) std::fprintf(out, "          %d\n", contact.state);
  std::fprintf(out, "        </DataArray>\n        <DataArray type=\"Float64\" Name=\"gap_m\" format=\"ascii\">\n");
  for (const auto& contact : contacts) std::fprintf(out, "          %.10g\n", contact.gap_m);
  std::fprintf(out, "        </DataArray>\n      </PointData>\n      <Points>\n");
  WriteVectorArray(out, "position_m", positions);
  std::fprintf(out, "      </Points>\n      <Cells>\n");
  std::fprintf(out, "        <DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n");
  for (int i = 0; i < count; ++i) std::fprintf(out, "          %d\n", i);
  std::fprintf(out, "        </DataArray>\n        <DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n");
  for (int i = 0; i < count; ++i) std::fprintf(out, "          %d\n", i + 1);
  std::fprintf(out, "        </DataArray>\n        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
  for (int i = 0; i < count; ++i) std::fprintf(out, "          1\n");  // VTK_VERTEX
  std::fprintf(out, "        </DataArray>\n      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n");
  Close(std::move(file), path);
}

VtkCollection::VtkCollection(std::string path) : path_(std::move(path)) { Write(); }

void VtkCollection::Add(double time, int part, const std::string& relative_file) {
  entries_.push_back({time, part, relative_file});
  Write();
}

void VtkCollection::Write() const {
  File file = OpenForWriting(path_);
  std::fprintf(file.get(), "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"1.0\">\n  <Collection>\n");
  for (const Entry& entry : entries_) {
    std::fprintf(file.get(), "    <DataSet timestep=\"%.10g\" part=\"%d\" file=\"%s\"/>\n", entry.time, entry.part,
                 entry.file.c_str());
  }
  std::fprintf(file.get(), "  </Collection>\n</VTKFile>\n");
  Close(std::move(file), path_);
}

}  // namespace hapco::io
