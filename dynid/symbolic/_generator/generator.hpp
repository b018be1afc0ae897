// Declarations shared by the translation units of the dynid symbolic generator (see generator.cpp).
// generator.cpp and gen_mass.cpp compile in parallel.
#pragma once

#include <pinocchio/autodiff/casadi.hpp>

#include <pinocchio/multibody.hpp>

#include <casadi/casadi.hpp>

#include <string>
#include <vector>

// Only the joint types a dynid specification can name (and Mimic, which the algorithms reference):
// every algorithm is instantiated for each type of the collection, so a short one compiles ~3x faster
// than Pinocchio's default collection of 25 types.  The algorithms themselves are the same.
template<typename _Scalar, int _Options>
struct DynidJointCollectionTpl
{
  typedef _Scalar Scalar;
  static constexpr int Options = _Options;
  typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 0> JointModelRX;
  typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 1> JointModelRY;
  typedef pinocchio::JointModelRevoluteTpl<Scalar, Options, 2> JointModelRZ;
  typedef pinocchio::JointModelRevoluteUnalignedTpl<Scalar, Options> JointModelRevoluteUnaligned;
  typedef pinocchio::JointModelPrismaticTpl<Scalar, Options, 0> JointModelPX;
  typedef pinocchio::JointModelPrismaticTpl<Scalar, Options, 1> JointModelPY;
  typedef pinocchio::JointModelPrismaticTpl<Scalar, Options, 2> JointModelPZ;
  typedef pinocchio::JointModelPrismaticUnalignedTpl<Scalar, Options> JointModelPrismaticUnaligned;
  typedef pinocchio::JointModelMimicTpl<Scalar, Options, DynidJointCollectionTpl> JointModelMimic;
  typedef boost::variant<JointModelRX, JointModelRY, JointModelRZ, JointModelRevoluteUnaligned, JointModelPX,
                         JointModelPY, JointModelPZ, JointModelPrismaticUnaligned,
                         boost::recursive_wrapper<JointModelMimic>>
    JointModelVariant;
  typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 0> JointDataRX;
  typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 1> JointDataRY;
  typedef pinocchio::JointDataRevoluteTpl<Scalar, Options, 2> JointDataRZ;
  typedef pinocchio::JointDataRevoluteUnalignedTpl<Scalar, Options> JointDataRevoluteUnaligned;
  typedef pinocchio::JointDataPrismaticTpl<Scalar, Options, 0> JointDataPX;
  typedef pinocchio::JointDataPrismaticTpl<Scalar, Options, 1> JointDataPY;
  typedef pinocchio::JointDataPrismaticTpl<Scalar, Options, 2> JointDataPZ;
  typedef pinocchio::JointDataPrismaticUnalignedTpl<Scalar, Options> JointDataPrismaticUnaligned;
  typedef pinocchio::JointDataMimicTpl<Scalar, Options, DynidJointCollectionTpl> JointDataMimic;
  typedef boost::variant<JointDataRX, JointDataRY, JointDataRZ, JointDataRevoluteUnaligned, JointDataPX,
                         JointDataPY, JointDataPZ, JointDataPrismaticUnaligned,
                         boost::recursive_wrapper<JointDataMimic>>
    JointDataVariant;
};

namespace pin = pinocchio;
using SX = ::casadi::SX;
using ModelD = pin::ModelTpl<double, 0, DynidJointCollectionTpl>;
using ModelS = pin::ModelTpl<SX, 0, DynidJointCollectionTpl>;
using DataS = pin::DataTpl<SX, 0, DynidJointCollectionTpl>;
using VecS = Eigen::Matrix<SX, Eigen::Dynamic, 1>;
using MatS = Eigen::Matrix<SX, Eigen::Dynamic, Eigen::Dynamic>;

// The symbolic inputs: flat CasADi vectors (the Function inputs) and their entries as Eigen vectors.
struct Symbols {
  SX q_, dq_, ddq_, tau_;
  VecS q, dq, ddq, tau;
};

inline SX to_sx(const MatS & m) {
  SX out(m.rows(), m.cols());
  pin::casadi::copy(m, out);
  return out;
}

// Writes DIR/NAME.casadi (Function::save).
void save(const std::string & dir, const std::string & name, const std::vector<SX> & in,
          const std::vector<std::string> & in_names, const std::vector<SX> & out,
          const std::vector<std::string> & out_names);

// Each runs one Pinocchio algorithm on (model, data) and saves its Function(s).
void generate_regressor(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir);
void generate_rnea_gravity(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir);
void generate_mass_matrix(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir);
void generate_aba(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir);
void generate_fk(const ModelS & model, DataS & data, const Symbols & s, const std::string & dir,
                 pin::JointIndex parent, const pin::SE3 & placement);
