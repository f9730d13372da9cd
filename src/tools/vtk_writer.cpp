#include "vtk_writer.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "active_tensegrity/core/outputs/observables.h"
#include "active_tensegrity/core/model/kinematics.h"

namespace active_tensegrity::tools
{
using namespace core;

namespace
{
const char* kClosing = "  </Collection>\n</VTKFile>\n";

enum Kind
{
  kStrut = 0,
  kCable = 1,
  kSpring = 2,
  kContact = 3
};

struct Cell
{
  std::vector<int> points;
  int kind = kStrut;
  double force = 0.0;
  double radius = 0.0;
  int member = 0;
};

std::string number(double v)
{
  if (!std::isfinite(v))
    v = 0.0;  // VTK readers differ on nan and inf; the writer's callers never pass them
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.10g", v);
  return buffer;
}

/// The points of a cell list as a VTK connectivity/offsets pair.
void writeCells(std::ostream& out, const char* tag, const std::vector<Cell>& cells)
{
  out << "      <" << tag << ">\n        <DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n";
  for (const Cell& c : cells)
    for (int p : c.points)
      out << " " << p;
  out << "\n        </DataArray>\n        <DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n";
  int offset = 0;
  for (const Cell& c : cells)
    out << " " << (offset += static_cast<int>(c.points.size()));
  out << "\n        </DataArray>\n      </" << tag << ">\n";
}
}  // namespace

VtkWriter::VtkWriter(const Model& model, const std::string& directory, const std::string& stem)
  : model_(model), directory_(directory), stem_(stem)
{
  std::error_code error;
  std::filesystem::create_directories(directory_, error);
  if (!std::filesystem::is_directory(directory_))
    throw std::runtime_error("cannot make the directory '" + directory_ + "'" +
                             (error ? ": " + error.message() : std::string()));
  // the collection, valid from the start: each write puts its entry over the closing tags and writes them
  // again (a run stopped early still leaves a collection of what it wrote)
  pvd_.open(collectionPath(), std::ios::trunc);
  pvd_ << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"1.0\" byte_order=\"LittleEndian\">\n"
       << "  <Collection>\n";
  pvd_tail_ = pvd_.tellp();
  pvd_ << kClosing << std::flush;
  if (!pvd_)
    throw std::runtime_error("cannot write '" + collectionPath() + "'");
  int struts = 0;
  for (const Body& b : model.bodies)
    strut_index_.push_back(b.kind == BodyKind::kStrut ? struts++ : -1);
}

std::string VtkWriter::collectionPath() const
{
  return (std::filesystem::path(directory_) / (stem_ + ".pvd")).string();
}

void VtkWriter::write(const State& state)
{
  // points: the nodes, then any other member point, then contact points
  std::vector<Vec3> points;
  std::vector<Vec3> contact_force;
  std::map<std::tuple<int, double, double, double>, int> index;
  const auto key = [](const PointRef& p) { return std::make_tuple(p.body, p.local.x(), p.local.y(), p.local.z()); };
  const auto point = [&](const PointRef& p)
  {
    const auto [it, added] = index.emplace(key(p), static_cast<int>(points.size()));
    if (added)
    {
      points.push_back(pointPosition(model_, p, state.q));
      contact_force.push_back(Vec3::Zero());
    }
    return it->second;
  };
  for (const Node& n : model_.nodes)
    point(n.point);

  std::vector<Cell> lines, verts;
  const std::vector<double> axial = strutAxialForces(model_, state);
  for (size_t b = 0; b < model_.bodies.size(); ++b)
  {
    const Body& body = model_.bodies[b];
    if (body.kind != BodyKind::kStrut)
      continue;
    const int bi = static_cast<int>(b);
    const double half = 0.5 * body.length;
    lines.push_back({ { point({ bi, Vec3(0.0, 0.0, -half) }), point({ bi, Vec3(0.0, 0.0, half) }) },
                      kStrut,
                      axial[b],
                      body.radius(),
                      strut_index_[b] });
  }
  const std::vector<CableState> cables = cableStates(model_, state);
  for (size_t c = 0; c < model_.cables.size(); ++c)
  {
    const Cable& cable = model_.cables[c];
    Cell cell;
    for (const PointRef& p : cable.points)
      cell.points.push_back(point(p));
    cell.kind = cable.area > 0.0 ? kCable : kSpring;
    cell.force = cables[c].tension;
    cell.radius = cable.area > 0.0 ? std::sqrt(cable.area / M_PI) : 0.0;
    cell.member = static_cast<int>(c);
    lines.push_back(cell);
  }
  for (const ContactPairState& c : activeContacts(model_, state))
  {
    for (const auto& [p, f] : { std::pair<Vec3, Vec3>{ c.point_a, c.force_on_a }, { c.point_b, -c.force_on_a } })
    {
      verts.push_back({ { static_cast<int>(points.size()) }, kContact, c.normal_force, 0.0, c.pair });
      points.push_back(p);
      contact_force.push_back(f);
    }
  }

  char name[32];
  std::snprintf(name, sizeof name, "_%06d.vtp", written());
  const std::string file = stem_ + name;
  const std::string path = (std::filesystem::path(directory_) / file).string();
  {
    std::ofstream out(path);
    out << "<?xml version=\"1.0\"?>\n"
        << "<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n"
        << "  <PolyData>\n"
        << "    <Piece NumberOfPoints=\"" << points.size() << "\" NumberOfVerts=\"" << verts.size()
        << "\" NumberOfLines=\"" << lines.size() << "\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">\n";
    out << "      <Points>\n        <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
    for (const Vec3& p : points)
      out << "          " << number(p.x()) << " " << number(p.y()) << " " << number(p.z()) << "\n";
    out << "        </DataArray>\n      </Points>\n";
    out << "      <PointData Vectors=\"contact_force\">\n"
        << "        <DataArray type=\"Float64\" Name=\"contact_force\" NumberOfComponents=\"3\" format=\"ascii\">\n";
    for (const Vec3& f : contact_force)
      out << "          " << number(f.x()) << " " << number(f.y()) << " " << number(f.z()) << "\n";
    out << "        </DataArray>\n      </PointData>\n";
    // cell data: vertices first, then lines (VTK's order of the cell kinds)
    std::vector<const Cell*> cells;
    for (const Cell& c : verts)
      cells.push_back(&c);
    for (const Cell& c : lines)
      cells.push_back(&c);
    out << "      <CellData Scalars=\"force\">\n";
    out << "        <DataArray type=\"Int32\" Name=\"kind\" format=\"ascii\">\n";
    for (const Cell* c : cells)
      out << " " << c->kind;
    out << "\n        </DataArray>\n        <DataArray type=\"Float64\" Name=\"force\" format=\"ascii\">\n";
    for (const Cell* c : cells)
      out << " " << number(c->force);
    out << "\n        </DataArray>\n        <DataArray type=\"Float64\" Name=\"radius\" format=\"ascii\">\n";
    for (const Cell* c : cells)
      out << " " << number(c->radius);
    out << "\n        </DataArray>\n        <DataArray type=\"Int32\" Name=\"member\" format=\"ascii\">\n";
    for (const Cell* c : cells)
      out << " " << c->member;
    out << "\n        </DataArray>\n      </CellData>\n";
    writeCells(out, "Verts", verts);
    writeCells(out, "Lines", lines);
    out << "    </Piece>\n  </PolyData>\n</VTKFile>\n";
    out.close();  // the buffer's last write fails here on a full disk
    if (!out)
      throw std::runtime_error("cannot write '" + path + "'");
  }
  ++written_;

  pvd_.seekp(pvd_tail_);
  pvd_ << "    <DataSet timestep=\"" << number(state.t) << "\" part=\"0\" file=\"" << file << "\"/>\n";
  pvd_tail_ = pvd_.tellp();
  pvd_ << kClosing << std::flush;
  if (!pvd_)
    throw std::runtime_error("cannot write '" + collectionPath() + "'");
}

}  // namespace active_tensegrity::tools
