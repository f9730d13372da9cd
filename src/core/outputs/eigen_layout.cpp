#include "active_tensegrity/core/outputs/eigen_layout.h"

#include "active_tensegrity/core/model/model.h"
#include "active_tensegrity/core/solvers/state.h"

namespace active_tensegrity::core
{
namespace
{
// Local to this file on purpose: a shared inline or template helper would be one symbol for the library
// and its users, and the dynamic linker may run a user's copy (compiled with the user's layout) here.
template <class T, class M>
TypeLayout layoutOf(M T::*member)
{
  const T object{};
  TypeLayout l;
  l.size = sizeof(T);
  l.align = alignof(T);
  l.member_offset = static_cast<std::size_t>(reinterpret_cast<const char*>(&(object.*member)) -
                                             reinterpret_cast<const char*>(&object));
  return l;
}
}  // namespace

EigenLayout libraryEigenLayout()
{
  EigenLayout l;
  l.max_static_align_bytes = EIGEN_MAX_STATIC_ALIGN_BYTES;
  l.probe = layoutOf(&EigenLayoutProbe::vector);
  l.constraint = layoutOf(&Constraint::coefficients);
  l.model = layoutOf(&Model::gravity);
  l.state = layoutOf(&State::natural);
  return l;
}

}  // namespace active_tensegrity::core
