#!/usr/bin/env python3
"""Checks specbake's KTX2 files with an independent reader.

    ktx2_validate.py SAMPLES_EXE      (run with build/pyenv/bin/python)

Runs SAMPLES_EXE (tests/python/ktx2_samples.cpp) into a temporary folder, then reads every
file with pyktx2 (PyPI, pure Python, pinned to 0.3.1 by scripts/setup.sh) and checks:
  - header, index, level index, DFD basic block and samples, key/value pairs as pyktx2 parses
    them, against what specbake's writer claims (claims.json) and against the KTX 2.0 rules;
  - the level bytes: plain levels as pyktx2 slices them, Zstandard levels decompressed with the
    `zstandard` package (its own build of zstd), against the source floats converted here with
    numpy (float16: IEEE round to nearest even; float32: the bits), alpha 1 for RGB sources.

pyktx2 0.3.1 reads only part of what the specification allows. This script extends it in
three places, each printed when it runs, and keeps the rest of its parsing as it is:
  1. its ColorModel enum lacks KHR_DF_MODEL_RGBSDA (1), the model of every uncompressed
     format, so parse_dfd fails on any RGBSDA file: the value is added;
  2. its get_stride knows only VK_FORMAT_R16G16B16A16_SFLOAT: VK_FORMAT_R32G32B32A32_SFLOAT
     (109, 16 bytes per texel) is added;
  3. its key/value padding is computed from the position modulo 8 (alignment 4 is passed in),
     which walks backwards after entries ending at 5, 6 or 7 mod 8: the spec's rule (pad to 4)
     replaces it.
It does not decompress Zstandard levels (it leaves levelImages empty): done here instead.
Exit 0: every check passed; 1: a check failed (each failure is printed).
"""
import enum
import json
import pathlib
import struct
import subprocess
import sys
import tempfile

import numpy as np
import pyktx2
import pyktx2.parser as P
import zstandard

failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def unpatched_probe(data):
    """What pyktx2 as published makes of a file (reported, not judged)."""
    try:
        P.parse_bytes(data)
        return "parses"
    except Exception as e:  # noqa: BLE001 - reporting whatever it raises
        return f"{type(e).__name__}: {e}"


def patch_pyktx2():
    members = {m.name: m.value for m in P.ColorModel}
    if 1 not in members.values():
        members["KHR_DF_MODEL_RGBSDA"] = 1
        P.ColorModel = enum.Enum("ColorModel", members)
        print("pyktx2 extension 1: ColorModel gains KHR_DF_MODEL_RGBSDA = 1")
    original_stride = P.get_stride

    def get_stride(fmt):
        if fmt == P.VkFormat.VK_FORMAT_R32G32B32A32_SFLOAT:
            return 16
        return original_stride(fmt)

    P.get_stride = get_stride
    print("pyktx2 extension 2: get_stride(VK_FORMAT_R32G32B32A32_SFLOAT) = 16")

    def get_padding_size(self, alignment):
        return (-self.pos) % alignment

    P.BytesReader.get_padding_size = get_padding_size
    print("pyktx2 extension 3: key/value padding to a multiple of 4 (pos % 4, not pos % 8)")


def expected_level(src, channels, vk_format):
    rgba = np.ones((src.size // channels, 4), dtype=np.float32)
    rgba[:, 2] = 0.0  # two channels: blue 0 (then overwritten where given), alpha 1
    rgba[:, :channels] = src.reshape(-1, channels)
    if vk_format == 97:
        return rgba.astype("<f2").tobytes()  # numpy: IEEE 754 round to nearest even
    return rgba.astype("<f4").tobytes()


def validate(folder, claim):
    name = claim["name"]
    data = (folder / f"{name}.ktx2").read_bytes()
    src = np.frombuffer((folder / f"{name}.f32").read_bytes(), dtype="<f4")
    k = P.parse_bytes(data)
    where = f"{name}:"

    # Header and index as pyktx2 reads them, against the writer's claims.
    check(k.vkFormat.value == claim["vkFormat"], f"{where} vkFormat {k.vkFormat} vs {claim['vkFormat']}")
    check(k.vkFormat.value in (97, 109), f"{where} vkFormat is R16G16B16A16_SFLOAT or R32G32B32A32_SFLOAT")
    check(k.typeSize == {97: 2, 109: 4}[k.vkFormat.value], f"{where} typeSize {k.typeSize}")
    for field in ("typeSize", "pixelWidth", "pixelHeight", "pixelDepth", "layerCount", "faceCount", "levelCount",
                  "dfdByteOffset", "dfdByteLength", "kvdByteOffset", "kvdByteLength"):
        check(getattr(k, field) == claim[field], f"{where} {field} {getattr(k, field)} vs claimed {claim[field]}")
    check(k.supercompressionScheme.value == claim["supercompressionScheme"], f"{where} supercompressionScheme")
    check(k.faceCount == 1 and k.levelCount == 1, f"{where} faces 1, levels 1")
    check(k.layerCount == 0 or k.pixelDepth == 0, f"{where} an array is of 2D textures")
    check(k.sgdByteOffset == 0 and k.sgdByteLength == 0, f"{where} no supercompression global data")
    check(k.supercompressionGlobalData == b"", f"{where} empty global data")
    check(len(k.levelIndices) == 1, f"{where} one level index entry")
    lvl = k.levelIndices[0]
    check(list(lvl) == claim["level"], f"{where} level index {tuple(lvl)} vs claimed {claim['level']}")
    texel = {97: 8, 109: 16}[k.vkFormat.value]
    texels = k.pixelWidth * k.pixelHeight * max(1, k.pixelDepth) * max(1, k.layerCount)
    check(lvl.uncompressedByteLength == texels * texel,
          f"{where} uncompressedByteLength = w*h*max(d,1)*max(layers,1)*{texel}")
    check(lvl.byteOffset + lvl.byteLength == len(data), f"{where} the level ends the file")
    check(lvl.byteOffset >= k.kvdByteOffset + k.kvdByteLength, f"{where} level after the key/value data")
    zstd = k.supercompressionScheme == P.SupercompressionScheme.Zstandard
    if not zstd:
        check(lvl.byteOffset % texel == 0, f"{where} level aligned to lcm({texel}, 4)")
        check(lvl.byteLength == lvl.uncompressedByteLength, f"{where} byteLength == uncompressedByteLength")

    # DFD: pyktx2's basic block and raw samples, plus the words the writer claims.
    dfd, samples = k.dfd
    words = list(struct.unpack(f"<{k.dfdByteLength // 4}I", data[k.dfdByteOffset:k.dfdByteOffset + k.dfdByteLength]))
    check(words == claim["dfd"], f"{where} DFD words differ from the claimed ones")
    check(words[0] == k.dfdByteLength, f"{where} dfdTotalSize == dfdByteLength")
    check(dfd.colorModel.value == 1, f"{where} colorModel RGBSDA")
    check(dfd.colorPrimaries == P.ColorPrimaries.KHR_DF_PRIMARIES_BT709, f"{where} primaries BT709")
    check(dfd.transferFunction == P.TransferFunction.KHR_DF_TRANSFER_LINEAR, f"{where} transfer LINEAR")
    check(dfd.flags == 0, f"{where} straight alpha")
    check((dfd.texelBlockDimension0, dfd.texelBlockDimension1, dfd.texelBlockDimension2,
           dfd.texelBlockDimension3) == (0, 0, 0, 0), f"{where} 1x1x1x1 texel block")
    check(dfd.bytesPlane0 == (0 if zstd else texel), f"{where} bytesPlane0 {dfd.bytesPlane0}")
    check(len(samples) == 4, f"{where} four samples")
    bits = texel * 2
    for i, (s, channel) in enumerate(zip(samples, (0, 1, 2, 15))):
        w0, pos, lower, upper = struct.unpack("<4I", s)
        check(w0 & 0xFFFF == i * bits, f"{where} sample {i} bitOffset")
        check((w0 >> 16) & 0xFF == bits - 1, f"{where} sample {i} bitLength")
        check((w0 >> 24) & 0xF == channel, f"{where} sample {i} channel")
        check(w0 >> 28 == 0xC, f"{where} sample {i} qualifiers FLOAT|SIGNED")
        check(pos == 0, f"{where} sample {i} position")
        check(struct.unpack("<f", struct.pack("<I", lower))[0] == -1.0, f"{where} sample {i} sampleLower -1.0f")
        check(struct.unpack("<f", struct.pack("<I", upper))[0] == 1.0, f"{where} sample {i} sampleUpper 1.0f")

    # Key/value data as pyktx2 reads it (values keep their NUL), in byte order of the keys.
    kv = {key: value for key, value in k.kv.items()}
    check(list(kv) == sorted(kv, key=lambda s: s.encode()), f"{where} keys in byte order")
    check(kv == {key: v.encode() + b"\0" for key, v in claim["kv"].items()}, f"{where} key/value pairs {kv}")
    check(kv.get("KTXwriter") == b"specbake samples\0", f"{where} KTXwriter")
    check(kv.get("specbake.case") == name.encode() + b"\0", f"{where} specbake.case")

    # Level bytes.
    raw = data[lvl.byteOffset:lvl.byteOffset + lvl.byteLength]
    if zstd:
        level = zstandard.ZstdDecompressor().decompress(raw, max_output_size=lvl.uncompressedByteLength)
    else:
        check(len(k.levelImages) == max(1, k.pixelDepth) * max(1, k.layerCount),
              f"{where} pyktx2 gives one image per slice or layer")
        level = b"".join(img.data for img in k.levelImages)
        check(all(img.width == k.pixelWidth and img.height == k.pixelHeight for img in k.levelImages),
              f"{where} image sizes")
    check(len(level) == lvl.uncompressedByteLength, f"{where} level size {len(level)}")
    want = expected_level(src, claim["channels"], k.vkFormat.value)
    if level != want:
        got = np.frombuffer(level, dtype="<f2" if texel == 8 else "<f4")
        exp = np.frombuffer(want, dtype="<f2" if texel == 8 else "<f4")
        bad = np.flatnonzero(got.view(np.uint16 if texel == 8 else np.uint32)
                             != exp.view(np.uint16 if texel == 8 else np.uint32))
        check(False, f"{where} {bad.size} level values differ from numpy's conversion, first at {bad[:5]}: "
                     f"{got[bad[:5]]} vs {exp[bad[:5]]}")
    print(f"{name}: {k.vkFormat.name} {k.pixelWidth}x{k.pixelHeight}x{k.pixelDepth} "
          f"{k.supercompressionScheme.name}, level {lvl.byteLength}/{lvl.uncompressedByteLength} bytes: checked")


def main():
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    print(f"pyktx2 {getattr(pyktx2, '__version__', '?')}, numpy {np.__version__}, zstandard {zstandard.__version__}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = pathlib.Path(tmp)
        subprocess.run([sys.argv[1], str(folder)], check=True)
        claims = json.loads((folder / "claims.json").read_text())
        check(len(claims) == 10, f"{len(claims)} sample files, expected 10")
        for claim in claims:
            print(f"{claim['name']}: pyktx2 as published: "
                  f"{unpatched_probe((folder / (claim['name'] + '.ktx2')).read_bytes())}")
        patch_pyktx2()
        for claim in claims:
            try:
                validate(folder, claim)
            except Exception as e:  # noqa: BLE001 - a reader error is a failed check
                check(False, f"{claim['name']}: {type(e).__name__}: {e}")
    print(f"{len(failures)} failed checks" if failures else "all checks passed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
