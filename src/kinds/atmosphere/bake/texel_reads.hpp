#pragma once
// The texels a double-reference recomputation reads. atmosphere.cl names every texture read
// with NOTE_TEXEL(tex, offset); compiled as C++ (reference.hpp) the macro calls note_texel,
// which, while a TexelReads is active on the calling thread, notes which of its textures was read
// and at which texel. A self-check runs its recomputations once with the reads noted, fetches
// exactly those texels from the device (a gather), and runs them again on the fetched values
// with the reads noted once more: the second run must read the same texels (the coordinates of
// a lookup depend on the geometry, not on the values), or the check is a programming error.
#include <algorithm>
#include <array>
#include <cstddef>
#include <stdexcept>
#include <vector>

namespace specbake::atmosphere {

class TexelReads {
 public:
  static constexpr int kTextures = 6;  // as Tex numbers them
  // bases[i]: the start of texture i as the recomputation sees it (null: not read), nch values a texel.
  TexelReads(const std::array<const double*, kTextures>& bases, int nch) : bases_(bases), nch_(nch) {}

  void note(const double* tex, std::ptrdiff_t offset) {
    for (int i = 0; i < kTextures; ++i)
      if (tex == bases_[i] && tex != nullptr) {
        texels_[i].push_back(static_cast<long long>(offset / nch_));
        return;
      }
    throw std::logic_error("a reference recomputation read a texture the self-check does not know");
  }
  // Each texture's texels, sorted, without repeats.
  std::array<std::vector<long long>, kTextures> sorted() const {
    auto out = texels_;
    for (auto& v : out) {
      std::sort(v.begin(), v.end());
      v.erase(std::unique(v.begin(), v.end()), v.end());
    }
    return out;
  }

  // The reads of the calling thread go to `r` while this lives.
  class Scope {
   public:
    explicit Scope(TexelReads& r) : previous_(active()) { active() = &r; }
    ~Scope() { active() = previous_; }
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;

   private:
    TexelReads* previous_;
  };
  static TexelReads*& active() {
    thread_local TexelReads* r = nullptr;
    return r;
  }

 private:
  std::array<const double*, kTextures> bases_;
  int nch_;
  std::array<std::vector<long long>, kTextures> texels_;
};

inline void note_texel(const double* tex, std::ptrdiff_t offset) {
  if (TexelReads* r = TexelReads::active()) r->note(tex, offset);
}

}  // namespace specbake::atmosphere

#define NOTE_TEXEL(tex, offset) note_texel((tex), (offset))
