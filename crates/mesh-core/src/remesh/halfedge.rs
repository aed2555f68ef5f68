//! The remesher's connectivity: a half-edge structure over a manifold, consistently oriented
//! triangle mesh with the three local operators (split, collapse, flip).
//!
//! Half-edges `2e` and `2e + 1` are the two sides of edge `e`; a half-edge with `face == NONE` is a
//! boundary half-edge (the outside of a boundary edge). Every vertex's `out` half-edge leaves it and
//! is its boundary half-edge when the vertex is on the boundary, so a walk `h → opp(prev(h))` from
//! `out[v]` visits every half-edge leaving `v`, once, counter-clockwise. Deleted elements are marked
//! and dropped by [`HalfEdgeMesh::compact`].

use std::collections::HashMap;

use super::RemeshError;

pub(super) const NONE: u32 = u32::MAX;

#[derive(Clone, Debug)]
pub(super) struct HalfEdgeMesh {
    pub pos: Vec<[f64; 3]>,
    to: Vec<u32>,
    next: Vec<u32>,
    prev: Vec<u32>,
    face: Vec<u32>,
    out: Vec<u32>,
    fh: Vec<u32>,
    edge_dead: Vec<bool>,
    /// Per edge: a feature (crease or boundary) edge.
    pub feature: Vec<bool>,
    /// Per vertex: never moved or removed.
    pub locked: Vec<bool>,
    live_faces: usize,
}

#[inline]
pub(super) fn opp(h: u32) -> u32 {
    h ^ 1
}

impl HalfEdgeMesh {
    /// Builds the structure; every face must have three distinct, in-range vertices.
    pub fn new(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Result<Self, RemeshError> {
        let nv = positions.len();
        let mut m = HalfEdgeMesh {
            pos: positions.to_vec(),
            to: Vec::with_capacity(faces.len() * 3),
            next: Vec::with_capacity(faces.len() * 3),
            prev: Vec::with_capacity(faces.len() * 3),
            face: Vec::with_capacity(faces.len() * 3),
            out: vec![NONE; nv],
            fh: Vec::with_capacity(faces.len()),
            edge_dead: Vec::new(),
            feature: Vec::new(),
            locked: vec![false; nv],
            live_faces: faces.len(),
        };
        let mut directed: HashMap<(u32, u32), u32> = HashMap::with_capacity(faces.len() * 3);
        for (fi, f) in faces.iter().enumerate() {
            let mut hs = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                if directed.contains_key(&(a, b)) {
                    return Err(RemeshError::NonManifoldEdge { a, b });
                }
                let h = match directed.get(&(b, a)) {
                    Some(&g) => opp(g),
                    None => {
                        let g = m.new_edge(b, a);
                        opp(g)
                    }
                };
                m.face[h as usize] = fi as u32;
                directed.insert((a, b), h);
                hs[k] = h;
            }
            for k in 0..3 {
                m.next[hs[k] as usize] = hs[(k + 1) % 3];
                m.prev[hs[(k + 1) % 3] as usize] = hs[k];
            }
            m.fh.push(hs[0]);
        }
        // Boundary half-edges: link each to the boundary half-edge leaving its target.
        let mut boundary_out = vec![NONE; nv];
        for h in 0..m.to.len() as u32 {
            if m.face[h as usize] == NONE {
                let from = m.from(h);
                if boundary_out[from as usize] != NONE {
                    return Err(RemeshError::NonManifoldVertex { vertex: from });
                }
                boundary_out[from as usize] = h;
            }
        }
        for h in 0..m.to.len() as u32 {
            if m.face[h as usize] == NONE {
                let n = boundary_out[m.to[h as usize] as usize];
                m.next[h as usize] = n;
                m.prev[n as usize] = h;
            }
        }
        let mut count = vec![0u32; nv];
        for h in 0..m.to.len() as u32 {
            let from = m.from(h) as usize;
            count[from] += 1;
            if m.out[from] == NONE {
                m.out[from] = h;
            }
        }
        for v in 0..nv {
            if boundary_out[v] != NONE {
                m.out[v] = boundary_out[v];
            }
        }
        // Manifold vertices: one fan reaches every half-edge leaving the vertex.
        for v in 0..nv {
            let start = m.out[v];
            if start == NONE {
                continue;
            }
            let mut h = start;
            let mut n = 0u32;
            loop {
                n += 1;
                h = opp(m.prev[h as usize]);
                if h == start || n > count[v] {
                    break;
                }
            }
            if n != count[v] {
                return Err(RemeshError::NonManifoldVertex { vertex: v as u32 });
            }
        }
        Ok(m)
    }

    fn new_edge(&mut self, a: u32, b: u32) -> u32 {
        let h = self.to.len() as u32;
        self.to.extend([b, a]);
        self.next.extend([NONE, NONE]);
        self.prev.extend([NONE, NONE]);
        self.face.extend([NONE, NONE]);
        self.edge_dead.push(false);
        self.feature.push(false);
        h
    }

    pub fn num_edges(&self) -> usize {
        self.edge_dead.len()
    }

    pub fn num_vertices(&self) -> usize {
        self.pos.len()
    }

    pub fn live_faces(&self) -> usize {
        self.live_faces
    }

    pub fn edge_live(&self, e: usize) -> bool {
        !self.edge_dead[e]
    }

    pub fn vertex_live(&self, v: usize) -> bool {
        self.out[v] != NONE
    }

    #[inline]
    pub fn to(&self, h: u32) -> u32 {
        self.to[h as usize]
    }

    #[inline]
    pub fn from(&self, h: u32) -> u32 {
        self.to[opp(h) as usize]
    }

    #[inline]
    pub fn next(&self, h: u32) -> u32 {
        self.next[h as usize]
    }

    #[inline]
    pub fn face_of(&self, h: u32) -> u32 {
        self.face[h as usize]
    }

    #[inline]
    pub fn is_boundary_halfedge(&self, h: u32) -> bool {
        self.face[h as usize] == NONE
    }

    /// The far edges `(a, b)` of the faces around a vertex (its outgoing half-edges `ring`, as
    /// [`Self::outgoing`] gives them; each face `(v, a, b)` counter-clockwise) that survive its
    /// collapse with `other`: boundary half-edges and the faces containing `other` left out.
    pub fn surviving_far_edges<'a>(
        &'a self,
        ring: &'a [u32],
        other: u32,
    ) -> impl Iterator<Item = (u32, u32)> + 'a {
        ring.iter()
            .filter(|&&g| !self.is_boundary_halfedge(g))
            .map(|&g| (self.to(g), self.to(self.next(g))))
            .filter(move |&(a, b)| a != other && b != other)
    }

    pub fn is_boundary_edge(&self, e: usize) -> bool {
        self.is_boundary_halfedge(2 * e as u32) || self.is_boundary_halfedge(2 * e as u32 + 1)
    }

    pub fn is_boundary_vertex(&self, v: u32) -> bool {
        let h = self.out[v as usize];
        h != NONE && self.is_boundary_halfedge(h)
    }

    /// The half-edges leaving `v`, counter-clockwise from `out[v]`, into `buf` (cleared first).
    pub fn outgoing(&self, v: u32, buf: &mut Vec<u32>) {
        buf.clear();
        let start = self.out[v as usize];
        if start == NONE {
            return;
        }
        let mut h = start;
        loop {
            buf.push(h);
            h = opp(self.prev[h as usize]);
            if h == start || buf.len() > self.to.len() {
                break;
            }
        }
    }

    pub fn valence(&self, v: u32) -> usize {
        let start = self.out[v as usize];
        if start == NONE {
            return 0;
        }
        let mut h = start;
        let mut n = 0;
        loop {
            n += 1;
            h = opp(self.prev[h as usize]);
            if h == start || n > self.to.len() {
                return n;
            }
        }
    }

    /// The corners of a live face in CCW order.
    pub fn face_vertices(&self, f: u32) -> [u32; 3] {
        let h = self.fh[f as usize];
        let h1 = self.next[h as usize];
        [self.from(h), self.to(h), self.to(h1)]
    }

    /// A half-edge of live face `f` (its first, from the first corner of [`Self::face_vertices`]).
    pub fn face_halfedge(&self, f: u32) -> u32 {
        self.fh[f as usize]
    }

    pub fn face_live(&self, f: usize) -> bool {
        self.fh[f] != NONE
    }

    pub fn num_face_slots(&self) -> usize {
        self.fh.len()
    }

    pub fn edge_length(&self, e: usize) -> f64 {
        let h = 2 * e as u32;
        dist(
            self.pos[self.from(h) as usize],
            self.pos[self.to(h) as usize],
        )
    }

    /// Whether boundary half-edge `h`'s boundary loop has exactly three edges (a triangular hole).
    pub fn boundary_loop_is_triangle(&self, h: u32) -> bool {
        let n = self.next(h);
        let nn = self.next(n);
        self.next(nn) == h
    }

    /// Splits edge `e` at `p`; returns the new vertex. The half of the edge toward `from(2e)`
    /// keeps index `e`, the other half is a new edge with the same feature flag; the edges to the
    /// opposite corners are new, not features.
    pub fn split(&mut self, e: usize, p: [f64; 3]) -> u32 {
        let h = 2 * e as u32;
        let o = h + 1;
        let b = self.to(h);
        let m = self.pos.len() as u32;
        self.pos.push(p);
        self.out.push(NONE);
        self.locked.push(false);
        let nh = self.new_edge(m, b); // nh: m→b, no: b→m
        let no = opp(nh);
        self.feature[(nh / 2) as usize] = self.feature[e];
        let (h_next, o_prev) = (self.next(h), self.prev[o as usize]);
        self.to[h as usize] = m;
        // Side of h.
        if let Some(f1) = self.face_opt(h) {
            let h1 = h_next; // b→c
            let h2 = self.next(h1); // c→a
            let c = self.to(h1);
            let t = self.new_edge(m, c); // t: m→c, t': c→m
            let tt = opp(t);
            let f3 = self.new_face();
            // f1 = (a, m, c): h, t, h2
            self.link_face(f1, [h, t, h2]);
            // f3 = (m, b, c): nh, h1, tt
            self.link_face(f3, [nh, h1, tt]);
        } else {
            // h: a→m, nh: m→b, both boundary.
            self.next[h as usize] = nh;
            self.prev[nh as usize] = h;
            self.next[nh as usize] = h_next;
            self.prev[h_next as usize] = nh;
            self.face[nh as usize] = NONE;
        }
        // Side of o (now m→a, preceded by no: b→m).
        if let Some(f2) = self.face_opt(o) {
            let o1 = self.next(o); // a→d
            let o2 = self.next(o1); // d→b
            let d = self.to(o1);
            let s = self.new_edge(d, m); // s: d→m, s': m→d
            let ss = opp(s);
            let f4 = self.new_face();
            // f2 = (m, a, d): o, o1, s
            self.link_face(f2, [o, o1, s]);
            // f4 = (b, m, d): no, ss, o2
            self.link_face(f4, [no, ss, o2]);
        } else {
            self.next[o_prev as usize] = no;
            self.prev[no as usize] = o_prev;
            self.next[no as usize] = o;
            self.prev[o as usize] = no;
            self.face[no as usize] = NONE;
        }
        if self.out[b as usize] == o {
            self.out[b as usize] = no;
        }
        self.out[m as usize] = if self.is_boundary_halfedge(nh) {
            nh
        } else if self.is_boundary_halfedge(o) {
            o
        } else {
            nh
        };
        m
    }

    fn face_opt(&self, h: u32) -> Option<u32> {
        let f = self.face[h as usize];
        (f != NONE).then_some(f)
    }

    fn new_face(&mut self) -> u32 {
        self.fh.push(NONE);
        self.live_faces += 1;
        (self.fh.len() - 1) as u32
    }

    fn link_face(&mut self, f: u32, hs: [u32; 3]) {
        for k in 0..3 {
            let (a, b) = (hs[k], hs[(k + 1) % 3]);
            self.next[a as usize] = b;
            self.prev[b as usize] = a;
            self.face[a as usize] = f;
        }
        self.fh[f as usize] = hs[0];
    }

    /// Flips interior edge `e`: the quad `a d b c` (edge `a b`, opposite corners `c`, `d`) gets the
    /// diagonal `c d`. The caller has checked that the flip is legal.
    pub fn flip(&mut self, e: usize) {
        let h = 2 * e as u32;
        let o = h + 1;
        let (f1, f2) = (self.face[h as usize], self.face[o as usize]);
        let h1 = self.next(h); // b→c
        let h2 = self.next(h1); // c→a
        let o1 = self.next(o); // a→d
        let o2 = self.next(o1); // d→b
        let (a, b) = (self.from(h), self.to(h));
        let (c, d) = (self.to(h1), self.to(o1));
        if self.out[a as usize] == h {
            self.out[a as usize] = o1;
        }
        if self.out[b as usize] == o {
            self.out[b as usize] = h1;
        }
        self.to[h as usize] = c; // h: d→c
        self.to[o as usize] = d; // o: c→d
        self.link_face(f1, [h, h2, o1]); // (d, c, a)
        self.link_face(f2, [o, o2, h1]); // (c, d, b)
    }

    /// Collapses half-edge `h` (`from(h)` is removed, its edges move to `to(h)`, which keeps its
    /// position). The caller has checked the link condition and the geometry.
    pub fn collapse(&mut self, h: u32, scratch: &mut Vec<u32>) {
        let o = opp(h);
        let v0 = self.from(h);
        let v1 = self.to(h);
        self.outgoing(v0, scratch);
        for &g in scratch.iter() {
            self.to[opp(g) as usize] = v1;
        }
        let mut keep_out;
        let mut others = [NONE; 2];
        // Side of h.
        if let Some(fl) = self.face_opt(h) {
            let h1 = self.next(h); // v1→vl
            let h2 = self.next(h1); // vl→v0 (now vl→v1)
            let x = opp(h2); // v0→vl
            self.replace(x, h1);
            let (ex, e1) = ((x / 2) as usize, (h1 / 2) as usize);
            self.feature[e1] |= self.feature[ex];
            self.edge_dead[ex] = true;
            let vl = self.to(h1);
            self.out[vl as usize] = opp(h1);
            others[0] = vl;
            self.kill_face(fl);
            keep_out = h1;
        } else {
            let (hp, hn) = (self.prev[h as usize], self.next(h));
            self.next[hp as usize] = hn;
            self.prev[hn as usize] = hp;
            keep_out = hn;
        }
        // Side of o.
        if let Some(fr) = self.face_opt(o) {
            let o1 = self.next(o); // v0→vr
            let o2 = self.next(o1); // vr→v1
            let w = opp(o1); // vr→v0 (now vr→v1)
            self.replace(w, o2);
            let (ew, e2) = ((w / 2) as usize, (o2 / 2) as usize);
            self.feature[e2] |= self.feature[ew];
            self.edge_dead[ew] = true;
            let vr = self.from(o2);
            self.out[vr as usize] = o2;
            others[1] = vr;
            self.kill_face(fr);
            if keep_out == NONE {
                keep_out = opp(o2);
            }
        } else {
            let (op, on) = (self.prev[o as usize], self.next(o));
            self.next[op as usize] = on;
            self.prev[on as usize] = op;
            if keep_out == NONE {
                keep_out = on;
            }
        }
        self.edge_dead[(h / 2) as usize] = true;
        self.out[v0 as usize] = NONE;
        self.out[v1 as usize] = keep_out;
        self.prefer_boundary_out(v1, scratch);
        for v in others {
            if v != NONE {
                self.prefer_boundary_out(v, scratch);
            }
        }
    }

    /// Puts half-edge `g` into the place of `x` (same face, same neighbours in the loop).
    fn replace(&mut self, x: u32, g: u32) {
        let (f, n, p) = (self.face[x as usize], self.next(x), self.prev[x as usize]);
        self.face[g as usize] = f;
        self.next[g as usize] = n;
        self.prev[g as usize] = p;
        self.next[p as usize] = g;
        self.prev[n as usize] = g;
        if f != NONE && self.fh[f as usize] == x {
            self.fh[f as usize] = g;
        }
    }

    fn kill_face(&mut self, f: u32) {
        self.fh[f as usize] = NONE;
        self.live_faces -= 1;
    }

    fn prefer_boundary_out(&mut self, v: u32, scratch: &mut Vec<u32>) {
        self.outgoing(v, scratch);
        if let Some(&b) = scratch.iter().find(|&&g| self.is_boundary_halfedge(g)) {
            self.out[v as usize] = b;
        }
    }

    /// The live vertices and faces, renumbered in order of their old indices.
    pub fn compact(&self) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let mut map = vec![NONE; self.pos.len()];
        let mut positions = Vec::new();
        for v in 0..self.pos.len() {
            if self.out[v] != NONE {
                map[v] = positions.len() as u32;
                positions.push(self.pos[v]);
            }
        }
        let faces = (0..self.fh.len())
            .filter(|&f| self.fh[f] != NONE)
            .map(|f| self.face_vertices(f as u32).map(|v| map[v as usize]))
            .collect();
        (positions, faces)
    }

    /// Checks every invariant (tests only).
    #[cfg(test)]
    pub fn check(&self) -> Result<(), String> {
        let mut buf = Vec::new();
        for h in 0..self.to.len() as u32 {
            if self.edge_dead[(h / 2) as usize] {
                continue;
            }
            let n = self.next(h);
            if self.prev[n as usize] != h {
                return Err(format!("prev(next({h})) != {h}"));
            }
            if self.from(n) != self.to(h) {
                return Err(format!("half-edge {h} and its next do not chain"));
            }
            if self.edge_dead[(n / 2) as usize] {
                return Err(format!("next of {h} is dead"));
            }
            let f = self.face[h as usize];
            if f != NONE {
                if self.fh[f as usize] == NONE {
                    return Err(format!("half-edge {h} in dead face {f}"));
                }
                if self.next(self.next(n)) != h || self.face[n as usize] != f {
                    return Err(format!("face {f} is not a triangle"));
                }
            } else if self.face[opp(h) as usize] == NONE {
                return Err(format!("edge {} has no face", h / 2));
            }
        }
        for v in 0..self.pos.len() as u32 {
            if self.out[v as usize] == NONE {
                continue;
            }
            self.outgoing(v, &mut buf);
            let mut seen = std::collections::HashSet::new();
            for &g in &buf {
                if self.from(g) != v || self.edge_dead[(g / 2) as usize] {
                    return Err(format!("ring of {v} holds {g}"));
                }
                if !seen.insert(self.to(g)) {
                    return Err(format!("vertex {v} has two edges to {}", self.to(g)));
                }
            }
            let nb = buf
                .iter()
                .filter(|&&g| self.is_boundary_halfedge(g))
                .count();
            if nb > 1 || (nb == 1 && !self.is_boundary_halfedge(self.out[v as usize])) {
                return Err(format!("vertex {v}: out is not its boundary half-edge"));
            }
        }
        let live = self.fh.iter().filter(|&&h| h != NONE).count();
        if live != self.live_faces {
            return Err("face count".into());
        }
        Ok(())
    }
}

#[inline]
pub(super) fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}
