#include "io/exr.hpp"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <ImfOutputFile.h>
#include <ImfStdIO.h>
#include <ImfStringAttribute.h>
#include <ImfThreading.h>
#include <Iex.h>

#include <algorithm>
#include <mutex>
#include <sstream>
#include <thread>

#include "core/errors.hpp"

namespace specbake {

namespace {
// OpenEXR compresses line blocks on its global thread pool (the file's bytes do not depend on
// the thread count: blocks are written in order); started once, one thread per core, ≤ 16.
int exr_threads() {
  static std::once_flag once;
  static int n = 0;
  std::call_once(once, [] {
    n = static_cast<int>(std::min(16u, std::max(1u, std::thread::hardware_concurrency())));
    Imf::setGlobalThreadCount(n);
  });
  return n;
}
}  // namespace

std::string exr_bytes(const ExrImage& img) {
  const std::size_t nc = img.channels.size();
  if (img.width <= 0 || img.height <= 0 || nc == 0 ||
      img.pixels.size() != static_cast<std::size_t>(img.width) * img.height * nc)
    throw JobError("EXR image has inconsistent size");
  if (!exr_size_allowed(img.width, img.height))
    throw JobError("an EXR image of " + std::to_string(img.width) + " x " + std::to_string(img.height) +
                   " pixels is more than its readers take (" + std::to_string(kMaxExrSide) + " per side, " +
                   std::to_string(kMaxExrPixels) + " in all); leave exr out of formats or use smaller sizes");
  try {
    Imf::Header header(img.width, img.height);
    // Float32 data is noise-like in its low mantissa bytes, which ZIP hardly shrinks: 0.4 % of a
    // 1024² diffraction term, 4–19 % of the default Earth's LUTs (11 % over the bundle's EXRs),
    // at 0.3–0.4 s per 12.6 MB LUT on a 2-core CPU, against 0.09 s uncompressed. So float32 goes
    // uncompressed (the .bin beside each EXR is the same data raw anyway); half data shrinks ~3×
    // under ZIP and keeps it.
    header.compression() = img.half ? Imf::ZIP_COMPRESSION : Imf::NO_COMPRESSION;
    const Imf::PixelType type = img.half ? Imf::HALF : Imf::FLOAT;
    for (const auto& c : img.channels) header.channels().insert(c, Imf::Channel(type));
    for (const auto& [k, v] : img.attributes) header.insert(k, Imf::StringAttribute(v));
    // Half storage needs a half buffer; float storage reads the floats directly.
    std::vector<Imath::half> halves;
    if (img.half) halves.assign(img.pixels.begin(), img.pixels.end());
    Imf::FrameBuffer fb;
    const std::size_t elem = img.half ? sizeof(Imath::half) : sizeof(float);
    char* base = img.half ? reinterpret_cast<char*>(halves.data())
                          : reinterpret_cast<char*>(const_cast<float*>(img.pixels.data()));
    for (std::size_t c = 0; c < nc; ++c)
      fb.insert(img.channels[c], Imf::Slice(type, base + c * elem, elem * nc, elem * nc * img.width));
    Imf::StdOSStream os;
    {
      Imf::OutputFile file(os, header, exr_threads());
      file.setFrameBuffer(fb);
      file.writePixels(img.height);
    }
    return os.str();
  } catch (const std::exception& e) {
    throw JobError(std::string("EXR encoding failed: ") + e.what());
  }
}

std::vector<std::string> exr_channels(const std::string& bytes) {
  try {
    Imf::StdISStream in;
    in.str(bytes);
    Imf::InputFile file(in);
    std::vector<std::string> names;
    for (auto it = file.header().channels().begin(); it != file.header().channels().end(); ++it)
      names.emplace_back(it.name());
    return names;
  } catch (const std::exception& e) {
    throw InputError({"", 0, 0, ""}, std::string("expected an OpenEXR image: ") + e.what());
  }
}

ExrImage exr_read(const std::string& bytes, const std::vector<std::string>& channels) {
  try {
    Imf::StdISStream in;
    in.str(bytes);
    Imf::InputFile file(in);
    const auto dw = file.header().dataWindow();
    ExrImage img;
    const long long w = static_cast<long long>(dw.max.x) - dw.min.x + 1, h = static_cast<long long>(dw.max.y) - dw.min.y + 1;
    // The header is untrusted: refuse sizes before allocating for them.
    if (!exr_size_allowed(w, h))
      throw InputError({"", 0, 0, ""}, "expected an EXR image of 1 to " + std::to_string(kMaxExrSide) +
                                           " pixels per side and at most " + std::to_string(kMaxExrPixels) +
                                           " pixels, header says " + std::to_string(w) + " x " + std::to_string(h));
    img.width = static_cast<int>(w);
    img.height = static_cast<int>(h);
    img.channels = channels;
    img.pixels.assign(static_cast<std::size_t>(img.width) * img.height * channels.size(), 0.0f);
    Imf::FrameBuffer fb;
    const std::size_t nc = channels.size();
    // Slice::Make places the data window's origin (any min.x, min.y) at the buffer's start
    // without forming an out-of-range pointer.
    for (std::size_t c = 0; c < nc; ++c)
      fb.insert(channels[c], Imf::Slice::Make(Imf::FLOAT, img.pixels.data() + c, dw, sizeof(float) * nc,
                                              sizeof(float) * nc * img.width));
    file.setFrameBuffer(fb);
    file.readPixels(dw.min.y, dw.max.y);
    const Imf::Channel* first = nc > 0 ? file.header().channels().findChannel(channels[0]) : nullptr;
    img.half = first && first->type == Imf::HALF;
    for (auto it = file.header().begin(); it != file.header().end(); ++it)
      if (auto* s = dynamic_cast<const Imf::StringAttribute*>(&it.attribute())) img.attributes[it.name()] = s->value();
    return img;
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError({"", 0, 0, ""}, std::string("expected an OpenEXR image: ") + e.what());
  }
}

}  // namespace specbake
