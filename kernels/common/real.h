/* real.h — the scalar vocabulary shared by OpenCL C kernels and their C++ reference.
 *
 * Every model's maths is written once, as plain functions over `real`, in a .cl file that
 *   - the OpenCL build compiles with real = float, or real = double when the host passes
 *     -DSPECBAKE_REAL_DOUBLE (only on devices with cl_khr_fp64), and
 *   - the C++ reference path #includes inside a namespace that defines real = double
 *     (see src/kinds/<kind>/reference.hpp).
 * Literals go through R(x) so that float builds stay in float.
 *
 * REQUIRE(condition) states a function's domain (as Bruneton's reference asserts each one):
 * live in the C++ reference, where a violation throws std::domain_error naming the condition
 * and the file (the including code must have <stdexcept>), and compiled out of the kernels.
 * Write conditions so that NaN fails them (x >= lo && x <= hi, not !(x < lo)).
 *
 * FN_HOT marks the few small functions an inner loop calls per sample (texture filters): the
 * OpenCL build must inline them (PoCL's compiler otherwise keeps them as calls), the C++ build
 * leaves it to the compiler. Only those: forcing every function inline multiplies the kernels'
 * build time (the path tracer's by ~3x) for no measured gain.
 */
#ifndef SPECBAKE_REAL_H
#define SPECBAKE_REAL_H

#ifdef __OPENCL_C_VERSION__
#  ifdef SPECBAKE_INJECTED_BUILD_FAILURE
#    error "build failure injected through SPECBAKE_INJECT_BUILD_FAILURE (fault test)"
#  endif
#  ifdef SPECBAKE_REAL_DOUBLE
#    pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
#  else
typedef float real;
#  endif
#  define GLOBAL __global
#  define LOCAL __local
#  define FN
#  define FN_HOT static inline __attribute__((always_inline))
#  define REQUIRE(condition) ((void)0)
#else
/* C++: the including namespace has `using real = double;` and the <cmath> names in scope. */
#  define GLOBAL
#  define LOCAL
#  define FN inline
#  define FN_HOT inline
#  define REQUIRE(condition) \
    ((condition) ? (void)0 : throw std::domain_error("domain check failed: " #condition " (" __FILE__ ")"))
#endif

#define R(x) ((real)(x))

#endif
