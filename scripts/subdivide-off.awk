# Usage: awk -f scripts/subdivide-off.awk IN.off > OUT.off (scripts/fetch-meshes.sh makes
# fixtures/meshes/external/bunny00_x4.off with it: the remeshing benchmark's ≥ 200k-face input).
# Midpoint (1:4) subdivision of a triangle OFF file: every edge gets its midpoint, every
# triangle becomes four. The surface is unchanged (the new triangles lie in the old ones).
{ sub(/#.*/, ""); for (i = 1; i <= NF; i++) tok[++n] = $i }
END {
  k = 1
  if (tok[k] ~ /OFF$/) k++
  nv = tok[k++]; nf = tok[k++]; k++
  for (v = 0; v < nv; v++) { x[v] = tok[k++]; y[v] = tok[k++]; z[v] = tok[k++] }
  m = nv
  for (f = 0; f < nf; f++) {
    if (tok[k] != 3) { print "subdivide: face " f " is not a triangle" > "/dev/stderr"; exit 1 }
    a[f] = tok[k + 1]; b[f] = tok[k + 2]; c[f] = tok[k + 3]; k += 4
    split(a[f] " " b[f] " " c[f], t, " ")
    for (j = 1; j <= 3; j++) {
      p = t[j]; q = t[j % 3 + 1]
      key = (p + 0 < q + 0) ? p "," q : q "," p
      if (!(key in mid)) {
        mid[key] = m
        x[m] = (x[p] + x[q]) / 2; y[m] = (y[p] + y[q]) / 2; z[m] = (z[p] + z[q]) / 2
        m++
      }
      e[f, j] = mid[key]
    }
  }
  print "OFF"
  print m, 4 * nf, 0
  for (v = 0; v < m; v++) printf "%.9g %.9g %.9g\n", x[v], y[v], z[v]
  for (f = 0; f < nf; f++) {
    ab = e[f, 1]; bc = e[f, 2]; ca = e[f, 3]
    print 3, a[f], ab, ca
    print 3, ab, b[f], bc
    print 3, ca, bc, c[f]
    print 3, ab, bc, ca
  }
}
