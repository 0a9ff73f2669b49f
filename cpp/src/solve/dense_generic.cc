// The dense kernels for the core's own target (dense_kernels.h).
#define FIVECAL_DENSE_ISA generic
#define FIVECAL_DENSE_NAME "generic"
#include "solve/dense_kernels.inc"

namespace fivecal {
namespace dense {

const Kernels& GenericKernels() { return generic::kTable; }

}  // namespace dense
}  // namespace fivecal
