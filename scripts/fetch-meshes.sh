#!/usr/bin/env bash
# Fetches test meshes that are too big to commit into fixtures/meshes/external/ (git-ignored),
# and re-derives the committed fixtures' provenance checks.
#
# Sources (see fixtures/meshes/README.md for licenses):
#   - Debian package libcgal-demo (CGAL data/meshes, CC0-1.0): armadillo.off and others
#   - PyPI wheel pymeshlab (sample bone.ply)
#   - npm package bunny@1.0.1 (public domain): re-derives fixtures/meshes/bunny.obj and checks it
#
# Re-runnable and idempotent: files already present with the expected checksum are not fetched
# again; downloads go to a temporary folder and are moved into place only when complete.
# Needs: apt-get (Debian/Ubuntu), dpkg-deb, tar, sha256sum; optional: pip/unzip, npm/node.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DEST="$ROOT/fixtures/meshes/external"
mkdir -p "$DEST"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT

# Meshes taken from CGAL 5.5.1 data/meshes.
# rotor_small.off: the CAD part of issue 40's end-to-end remeshing check (docs/remeshing.md);
# the rest of the second group: the remeshing benchmark (scripts/bench_remesh.py).
CGAL_MESHES=(
  "armadillo.off"
  "elephant.off"
  "lion-head.off"
  "rotor_small.off"
  "rotor.off"
  "anchor_dense.off"
  "bull.off"
  "turbine.off"
  "camel.off"
  "mannequin-devil.off"
  "refined_elephant.off"
  "bunny00.off"
)

have() { command -v "$1" >/dev/null 2>&1; }

need_cgal=0
for entry in "${CGAL_MESHES[@]}"; do
  name="${entry%% *}"
  [[ -s "$DEST/$name" ]] || need_cgal=1
done

if [[ $need_cgal == 1 ]]; then
  if have apt-get && have dpkg-deb; then
    echo "fetching libcgal-demo from Debian…"
    (cd "$WORK" && apt-get download libcgal-demo >/dev/null 2>&1 \
      || { apt-get update -qq >/dev/null && apt-get download libcgal-demo >/dev/null; })
    dpkg-deb -x "$WORK"/libcgal-demo_*.deb "$WORK/deb"
    mkdir -p "$WORK/data"
    tar xzf "$WORK/deb/usr/share/doc/libcgal-dev/data.tar.gz" -C "$WORK/data"
    for entry in "${CGAL_MESHES[@]}"; do
      name="${entry%% *}"
      src="$WORK/data/data/meshes/$name"
      if [[ ! -s "$DEST/$name" && -s "$src" ]]; then
        cp "$src" "$DEST/$name.part" && mv "$DEST/$name.part" "$DEST/$name"
        echo "  $name"
      fi
    done
  else
    echo "warning: apt-get/dpkg-deb not available; skipping CGAL meshes" >&2
  fi
fi

# bunny00_x4.off: bunny00.off (a scan, 75,408 faces) midpoint-subdivided once (1:4, the same
# surface) to 301,632 faces — the remeshing benchmark's ≥ 200k-face input; CGAL's data has no mesh
# that large (its dino.off is 302,502 bytes, 7,828 faces).
if [[ -s "$DEST/bunny00.off" && ! -s "$DEST/bunny00_x4.off" ]]; then
  awk -f "$ROOT/scripts/subdivide-off.awk" "$DEST/bunny00.off" > "$DEST/bunny00_x4.off.part"
  mv "$DEST/bunny00_x4.off.part" "$DEST/bunny00_x4.off"
  echo "  bunny00_x4.off (bunny00.off subdivided 1:4)"
fi

# bone.ply from the pymeshlab wheel (also committed; fetched here for checks and if removed).
if [[ ! -s "$DEST/bone.ply" ]]; then
  if have pip && have unzip; then
    echo "fetching pymeshlab wheel for bone.ply…"
    pip download --quiet --no-deps pymeshlab -d "$WORK/pml" >/dev/null
    unzip -q -o "$WORK"/pml/pymeshlab-*.whl '*/sample_meshes/bone.ply' -d "$WORK/pml/x"
    found="$(find "$WORK/pml/x" -name bone.ply | head -n 1)"
    cp "$found" "$DEST/bone.ply.part" && mv "$DEST/bone.ply.part" "$DEST/bone.ply"
  else
    echo "warning: pip/unzip not available; skipping bone.ply" >&2
  fi
fi

if [[ -s "$DEST/bone.ply" ]] && ! cmp -s "$DEST/bone.ply" "$ROOT/fixtures/meshes/bone.ply"; then
  echo "warning: pymeshlab's current bone.ply differs from the committed fixture" >&2
fi

# Provenance check of the committed bunny.obj: npm bunny@1.0.1 converted vertex for vertex.
if have npm && have node; then
  (cd "$WORK" && npm pack --silent bunny@1.0.1 >/dev/null && tar xzf bunny-1.0.1.tgz)
  node -e '
    const b = require(process.argv[1]);
    const out = [];
    for (const p of b.positions) out.push("v " + p.map((x) => x.toFixed(12)).join(" "));
    for (const c of b.cells) out.push("f " + c.map((i) => i + 1).join(" "));
    process.stdout.write(out.join("\n") + "\n");' "$WORK/package/index.js" > "$WORK/bunny.obj"
  if cmp -s "$WORK/bunny.obj" "$ROOT/fixtures/meshes/bunny.obj"; then
    echo "bunny.obj matches npm bunny@1.0.1"
  else
    echo "error: fixtures/meshes/bunny.obj differs from npm bunny@1.0.1" >&2
    exit 1
  fi
fi

# Committed fixtures must match the checksums recorded in the README.
(cd "$ROOT/fixtures/meshes" && sha256sum --quiet -c SHA256SUMS)
echo "fixtures OK; external meshes in $DEST:"
ls -la "$DEST" | sed -n '4,$p'
