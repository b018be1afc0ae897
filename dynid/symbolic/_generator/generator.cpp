// dynid symbolic generator.
//
// Reads a kinematic-tree specification written by dynid (dynid/symbolic/spec.py), builds the
// Pinocchio model, casts it to Scalar = casadi::SX and runs Pinocchio's own algorithms on CasADi
// symbols.  Every result is written as a named casadi::Function (Function::save) that the Python
// casadi module loads.  Built once per environment by dynid/symbolic/build.py.
//
// Two translation units that compile in parallel, about equally long: this file (the specification,
// the regressor, inverse dynamics, gravity and kinematics) and gen_mass.cpp (mass matrix, forward dynamics).
//
// Usage: dynid-generator SPEC_FILE OUT_DIR
//
// Specification (whitespace separated, one record per line):
//   dynid-spec 1
//   gravity gx gy gz
//   joint NAME TYPE PARENT R00 R01 R02 R10 R11 R12 R20 R21 R22 px py pz ax ay az
//   inertia m mcx mcy mcz Ixx Ixy Iyy Ixz Iyz Izz        (dynamic parameters of the last joint's body)
//   armature VALUE                                       (of the last joint)
//   tool NAME PARENT R00 .. R22 px py pz                 (placement of the tool frame in joint PARENT)
// TYPE is one of RX RY RZ PX PY PZ RU PU (RU / PU: unaligned axis a).
#include "generator.hpp"

#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/regressor.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

struct Tool {
  std::string name = "tool";
  pin::JointIndex parent = 0;
  pin::SE3 placement = pin::SE3::Identity();
};

[[noreturn]] void fail(const std::string & msg) { throw std::runtime_error(msg); }

pin::SE3 read_se3(std::istream & in) {
  Eigen::Matrix3d R;
  Eigen::Vector3d p;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) in >> R(i, j);
  in >> p[0] >> p[1] >> p[2];
  if (!in) fail("could not read a placement");
  return pin::SE3(R, p);
}

ModelD read_spec(const std::string & path, Tool & tool) {
  std::ifstream file(path);
  if (!file) fail("cannot open the specification " + path);
  ModelD model;
  std::string line;
  bool header = false;
  pin::JointIndex last = 0;
  while (std::getline(file, line)) {
    std::istringstream in(line);
    std::string key;
    if (!(in >> key) || key[0] == '#') continue;
    if (key == "dynid-spec") {
      int version = 0;
      in >> version;
      if (version != 1) fail("unsupported specification version");
      header = true;
    } else if (key == "gravity") {
      Eigen::Vector3d g;
      in >> g[0] >> g[1] >> g[2];
      model.gravity.linear(g);
    } else if (key == "joint") {
      std::string name, type;
      long parent = -1;
      in >> name >> type >> parent;
      const pin::SE3 placement = read_se3(in);
      Eigen::Vector3d axis;
      in >> axis[0] >> axis[1] >> axis[2];
      if (!in || parent < 0 || parent > static_cast<long>(model.njoints) - 1)
        fail("bad joint record: " + line);
      const auto p = static_cast<pin::JointIndex>(parent);
      if (type == "RX") last = model.addJoint(p, pin::JointModelRX(), placement, name);
      else if (type == "RY") last = model.addJoint(p, pin::JointModelRY(), placement, name);
      else if (type == "RZ") last = model.addJoint(p, pin::JointModelRZ(), placement, name);
      else if (type == "PX") last = model.addJoint(p, pin::JointModelPX(), placement, name);
      else if (type == "PY") last = model.addJoint(p, pin::JointModelPY(), placement, name);
      else if (type == "PZ") last = model.addJoint(p, pin::JointModelPZ(), placement, name);
      else if (type == "RU")
        last = model.addJoint(p, pin::JointModelRevoluteUnaligned(axis), placement, name);
      else if (type == "PU")
        last = model.addJoint(p, pin::JointModelPrismaticUnaligned(axis), placement, name);
      else fail("unknown joint type " + type);
    } else if (key == "inertia") {
      Eigen::Matrix<double, 10, 1> v;
      for (int i = 0; i < 10; ++i) in >> v[i];
      if (!in || last == 0) fail("bad inertia record: " + line);
      // Dynamic parameters about the joint frame; a massless body contributes nothing.
      if (v[0] > 0) model.appendBodyToJoint(last, pin::Inertia::FromDynamicParameters(v));
    } else if (key == "armature") {
      double a = 0;
      in >> a;
      if (!in || last == 0) fail("bad armature record: " + line);
      model.armature[model.joints[last].idx_v()] = a;
    } else if (key == "tool") {
      long parent = -1;
      in >> tool.name >> parent;
      tool.placement = read_se3(in);
      if (parent < 0 || parent > static_cast<long>(model.njoints) - 1) fail("bad tool record");
      tool.parent = static_cast<pin::JointIndex>(parent);
    } else {
      fail("unknown record " + key);
    }
  }
  if (!header) fail("the file is not a dynid specification");
  if (model.nq != model.nv) fail("only joints with nq == nv are supported");
  return model;
}

VecS symbols(const std::string & name, long n, SX & flat) {
  flat = SX::sym(name, n);
  VecS v(n);
  for (long i = 0; i < n; ++i) v[i] = flat(i);
  return v;
}

}  // namespace

void save(const std::string & dir, const std::string & name, const std::vector<SX> & in,
          const std::vector<std::string> & in_names, const std::vector<SX> & out,
          const std::vector<std::string> & out_names) {
  ::casadi::Function f(name, in, out, in_names, out_names);
  f.save(dir + "/" + name + ".casadi");
}


void generate_regressor(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir) {
  // Joint-torque regressor Y(q, dq, ddq), n x 10n, Pinocchio's parameter order per joint:
  // m, m c_x, m c_y, m c_z, Ixx, Ixy, Iyy, Ixz, Iyz, Izz about the joint frame.
  pin::computeJointTorqueRegressor(model, data, s.q, s.dq, s.ddq);
  save(dir, "regressor", {s.q_, s.dq_, s.ddq_}, {"q", "dq", "ddq"}, {to_sx(data.jointTorqueRegressor)}, {"Y"});
}

void generate_rnea_gravity(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir) {
  // Inverse dynamics with the model's own inertias and armature.
  pin::rnea(model, data, s.q, s.dq, s.ddq);
  save(dir, "rnea", {s.q_, s.dq_, s.ddq_}, {"q", "dq", "ddq"}, {to_sx(data.tau)}, {"tau"});

  pin::computeGeneralizedGravity(model, data, s.q);
  save(dir, "gravity", {s.q_}, {"q"}, {to_sx(data.g)}, {"g"});
}

void generate_fk(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir,
                 pin::JointIndex parent, const pin::SE3 & placement) {
  // Forward kinematics of the tool frame: position (3) and rotation matrix (3 x 3) in the base.
  pin::forwardKinematics(model, data, s.q);
  const pin::SE3Tpl<SX> oMt = data.oMi[parent] * placement.cast<SX>();
  save(dir, "fk", {s.q_}, {"q"}, {to_sx(oMt.translation()), to_sx(oMt.rotation())}, {"p", "R"});
}

int main(int argc, char ** argv) {
  if (argc != 3) {
    std::cerr << "usage: dynid-generator SPEC_FILE OUT_DIR\n";
    return 2;
  }
  try {
    Tool tool;
    const ModelD model_d = read_spec(argv[1], tool);
    const std::string dir = argv[2];
    const ModelS model = model_d.cast<SX>();
    DataS data(model);
    const long n = model.nv;

    Symbols s;
    s.q = symbols("q", n, s.q_);
    s.dq = symbols("dq", n, s.dq_);
    s.ddq = symbols("ddq", n, s.ddq_);
    s.tau = symbols("tau", n, s.tau_);

    // The same algorithms in the same order on the same data as a single file would run them.
    generate_regressor(model, data, s, dir);
    generate_rnea_gravity(model, data, s, dir);
    generate_mass_matrix(model, data, s, dir);
    generate_aba(model, data, s, dir);
    generate_fk(model, data, s, dir, tool.parent, tool.placement);
  } catch (const std::exception & e) {
    std::cerr << "dynid-generator: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
