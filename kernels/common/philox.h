/* philox.h — the Philox4x32-10 counter-based random number generator (J. K. Salmon,
 * M. A. Moraes, R. O. Dror, D. E. Shaw, "Parallel random numbers: as easy as 1, 2, 3", SC 2011),
 * written once for OpenCL C and C++ so that a kernel and its host reference draw the same
 * numbers.
 *
 * philox4x32_10(counter, key) is a bijection of the 128-bit counter for each 64-bit key: ten
 * rounds of two 32 × 32 → 64-bit multiplications (multipliers 0xD2511F53, 0xCD9E8D57) with the
 * Weyl key schedule (0x9E3779B9, 0xBB67AE85). Its output for the published known-answer
 * vectors is checked in tests/atmosphere/truth_test.cpp.
 *
 * PhiloxStream: one independent stream per (key, c1, c2, c3); draw i of the stream is word
 * i mod 4 of philox4x32_10({i / 4, c1, c2, c3}, key).
 */
#ifndef SPECBAKE_PHILOX_H
#define SPECBAKE_PHILOX_H

#ifdef __OPENCL_C_VERSION__
typedef uint philox_u32;
#  define PHILOX_FN
#  define PHILOX_MULHI(a, b) mul_hi((a), (b))
#else
#  include <cstdint>
typedef std::uint32_t philox_u32;
#  define PHILOX_FN inline
#  define PHILOX_MULHI(a, b) ((philox_u32)(((std::uint64_t)(a) * (std::uint64_t)(b)) >> 32))
#endif

#define PHILOX_M0 0xD2511F53u
#define PHILOX_M1 0xCD9E8D57u
#define PHILOX_W0 0x9E3779B9u
#define PHILOX_W1 0xBB67AE85u

PHILOX_FN void philox4x32_10(const philox_u32* counter, const philox_u32* key, philox_u32* out) {
  philox_u32 c0 = counter[0], c1 = counter[1], c2 = counter[2], c3 = counter[3];
  philox_u32 k0 = key[0], k1 = key[1];
  for (int round = 0; round < 10; ++round) {
    if (round > 0) {
      k0 += PHILOX_W0;
      k1 += PHILOX_W1;
    }
    const philox_u32 hi0 = PHILOX_MULHI(PHILOX_M0, c0), lo0 = PHILOX_M0 * c0;
    const philox_u32 hi1 = PHILOX_MULHI(PHILOX_M1, c2), lo1 = PHILOX_M1 * c2;
    c0 = hi1 ^ c1 ^ k0;
    c1 = lo1;
    c2 = hi0 ^ c3 ^ k1;
    c3 = lo0;
  }
  out[0] = c0;
  out[1] = c1;
  out[2] = c2;
  out[3] = c3;
}

typedef struct {
  philox_u32 counter[4];
  philox_u32 key[2];
  philox_u32 block[4];
  int used; /* words of `block` already handed out */
} PhiloxStream;

PHILOX_FN void philox_stream_init(PhiloxStream* s, philox_u32 key0, philox_u32 key1, philox_u32 c1, philox_u32 c2,
                                  philox_u32 c3) {
  s->counter[0] = 0u;
  s->counter[1] = c1;
  s->counter[2] = c2;
  s->counter[3] = c3;
  s->key[0] = key0;
  s->key[1] = key1;
  s->used = 4;
}

PHILOX_FN philox_u32 philox_next(PhiloxStream* s) {
  if (s->used == 4) {
    philox4x32_10(s->counter, s->key, s->block);
    s->counter[0] += 1u;
    s->used = 0;
  }
  return s->block[s->used++];
}

#endif
