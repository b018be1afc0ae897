// The mass-matrix algorithms of the dynid symbolic generator (see generator.cpp): a translation unit
// of its own, compiled in parallel with generator.cpp.
#include "generator.hpp"

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>

void generate_mass_matrix(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir) {
  pin::crba(model, data, s.q, pin::Convention::WORLD);
  MatS M = data.M;
  M.triangularView<Eigen::StrictlyLower>() = M.transpose().triangularView<Eigen::StrictlyLower>();
  save(dir, "mass_matrix", {s.q_}, {"q"}, {to_sx(M)}, {"M"});
}

void generate_aba(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir) {
  pin::aba(model, data, s.q, s.dq, s.tau, pin::Convention::WORLD);
  save(dir, "aba", {s.q_, s.dq_, s.tau_}, {"q", "dq", "tau"}, {to_sx(data.ddq)}, {"ddq"});
}
