#!/usr/bin/env python3
"""scripts/benchmarks.py: a measured record carries what the page needs, the page is rendered from
the records, and the committed docs/benchmarks.md is what the committed records render to.

    benchmarks_test.py SPECBAKE ROOT
"""
import json
import subprocess
import sys
import tempfile
from pathlib import Path

specbake, root = sys.argv[1], Path(sys.argv[2])
script = root / "scripts" / "benchmarks.py"


def run(*args, ok=True):
    p = subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True)
    if ok and p.returncode != 0:
        sys.exit(f"benchmarks.py {' '.join(args)} exited {p.returncode}:\n{p.stdout}{p.stderr}")
    return p


# The committed page is generated: render --check passes on the repository as it is.
run("render", "--check")

with tempfile.TemporaryDirectory() as tmp:
    records, page = Path(tmp) / "records.jsonl", Path(tmp) / "benchmarks.md"
    common = ["--records", str(records), "--page", str(page)]
    run(*common, "measure", "--only", "dispersion", "--repeats", "2", "--specbake", specbake, "--device", "cpu")
    recs = [json.loads(l) for l in records.read_text().splitlines()]
    assert len(recs) == 1, recs
    r = recs[0]
    for key in ("target", "date", "version", "machine", "figure", "unit", "spread", "runs", "load_before", "details"):
        assert key in r, f"record lacks {key}: {r}"
    assert r["target"] == "dispersion" and r["unit"] == "s" and r["runs"] == 2, r
    # the figure is the median of the warm runs' job seconds, read from their manifests
    warm = [w["bake_s"] for w in r["details"]["warm"]]
    assert len(warm) == 2 and all(w > 0 for w in warm), warm
    assert abs(r["figure"] - sorted(warm)[0] - (sorted(warm)[1] - sorted(warm)[0]) / 2) < 1e-12, (r["figure"], warm)
    assert r["spread"] == [min(warm), max(warm)], r["spread"]
    assert r["machine"]["device"] and r["machine"]["class"].startswith("cpu"), r["machine"]

    # cold runs, each into an empty output folder: the figure is their median, the first one's
    # facts stay under details.cold and the others follow
    run(*common, "measure", "--only", "dispersion", "--repeats", "0", "--cold-runs", "3", "--specbake", specbake,
        "--device", "cpu")
    c = [json.loads(l) for l in records.read_text().splitlines()][-1]
    colds = [c["details"]["cold"]] + c["details"]["more_cold"]
    assert c["runs"] == 3 and len(colds) == 3 and not c["details"]["warm"], c
    assert c["figure"] == sorted(x["bake_s"] for x in colds)[1], (c["figure"], colds)
    assert c["spread"] == [min(x["bake_s"] for x in colds), max(x["bake_s"] for x in colds)], c["spread"]

    run(*common, "render")
    text = page.read_text()
    section = text.split("## Bundled dispersion configs", 1)[1].split("\n## ", 1)[0]
    assert f"`{r['version']}`" in section and r["date"] in section, section
    assert "Not measured yet." in text.split("## Bundled diffraction configs", 1)[1], "an unmeasured target says so"

    # a page that is not what the records render to is refused
    page.write_text(text.replace("Benchmarks", "Benchmark", 1))
    p = run(*common, "render", "--check", ok=False)
    assert p.returncode != 0 and "not what" in p.stderr, (p.returncode, p.stderr)

    # an unknown target is refused, naming it
    p = run(*common, "measure", "--only", "no-such-target", "--specbake", specbake, ok=False)
    assert p.returncode != 0 and "no-such-target" in p.stderr, p.stderr
print("benchmarks.py: record, page and check as documented")
