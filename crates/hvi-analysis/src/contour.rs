//! Fields on a rectilinear grid: bilinear interpolation and contour lines (marching squares
//! with linear interpolation along cell edges, saddles resolved by the cell's mean), joined
//! into polylines. Pure functions on numbers; `plot` draws them, `validity` exports them.

use std::collections::HashMap;

/// Values z on the grid x (columns) by y (rows): `z[row][col]` at `(x[col], y[row])`. NaN marks
/// a missing value (a failed run; JSON null); cells touching one are left out.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Field {
    /// Column coordinates, strictly increasing.
    pub x: Vec<f64>,
    /// Row coordinates, strictly increasing.
    pub y: Vec<f64>,
    /// Values, `z[row][col]`.
    pub z: Vec<Vec<f64>>,
}

/// A point (x, y).
pub type Point = (f64, f64);

/// A cell edge: horizontal from (col, row) to (col + 1, row), or vertical from (col, row) to
/// (col, row + 1). Crossing points are keyed by edge, so neighbouring cells share them exactly.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Edge {
    H(usize, usize),
    V(usize, usize),
}

impl Field {
    /// Builds a field, checking the shape and that the coordinates increase.
    pub fn new(x: Vec<f64>, y: Vec<f64>, z: Vec<Vec<f64>>) -> Option<Field> {
        let inc = |v: &[f64]| v.windows(2).all(|w| w[0] < w[1]);
        if x.is_empty() || y.is_empty() || !inc(&x) || !inc(&y) || z.len() != y.len() {
            return None;
        }
        if z.iter().any(|row| row.len() != x.len()) {
            return None;
        }
        Some(Field { x, y, z })
    }

    /// Every finite value, row by row.
    pub fn finite_values(&self) -> impl Iterator<Item = f64> + '_ {
        self.z.iter().flatten().copied().filter(|v| v.is_finite())
    }

    /// The smallest and largest finite value.
    pub fn range(&self) -> Option<(f64, f64)> {
        self.finite_values().fold(None, |r, v| match r {
            None => Some((v, v)),
            Some((lo, hi)) => Some((f64::min(lo, v), f64::max(hi, v))),
        })
    }

    fn locate(c: &[f64], v: f64) -> Option<(usize, f64)> {
        if c.len() < 2 || v < c[0] || v > c[c.len() - 1] {
            return None;
        }
        let i = c.partition_point(|&a| a <= v).clamp(1, c.len() - 1) - 1;
        Some((i, (v - c[i]) / (c[i + 1] - c[i])))
    }

    /// Bilinear interpolation at (x, y); None outside the grid or in a cell with a missing
    /// corner.
    pub fn at(&self, x: f64, y: f64) -> Option<f64> {
        let (i, s) = Field::locate(&self.x, x)?;
        let (j, t) = Field::locate(&self.y, y)?;
        let z = |jj: usize, ii: usize| self.z[jj][ii];
        let v = (1.0 - s) * (1.0 - t) * z(j, i)
            + s * (1.0 - t) * z(j, i + 1)
            + (1.0 - s) * t * z(j + 1, i)
            + s * t * z(j + 1, i + 1);
        v.is_finite().then_some(v)
    }

    fn point(&self, e: Edge, level: f64) -> Point {
        let (a, b, pa, pb) = match e {
            Edge::H(i, j) => (
                self.z[j][i],
                self.z[j][i + 1],
                (self.x[i], self.y[j]),
                (self.x[i + 1], self.y[j]),
            ),
            Edge::V(i, j) => (
                self.z[j][i],
                self.z[j + 1][i],
                (self.x[i], self.y[j]),
                (self.x[i], self.y[j + 1]),
            ),
        };
        let t = if b == a { 0.5 } else { (level - a) / (b - a) };
        (pa.0 + t * (pb.0 - pa.0), pa.1 + t * (pb.1 - pa.1))
    }

    fn edge_segments(&self, level: f64) -> Vec<[Edge; 2]> {
        let mut segs = Vec::new();
        for j in 0..self.y.len().saturating_sub(1) {
            for i in 0..self.x.len().saturating_sub(1) {
                let c = [
                    self.z[j][i],
                    self.z[j][i + 1],
                    self.z[j + 1][i + 1],
                    self.z[j + 1][i],
                ];
                if c.iter().any(|v| !v.is_finite()) {
                    continue;
                }
                let above = c.map(|v| v >= level);
                // Edges in order around the cell: bottom, right, top, left.
                let edges = [
                    Edge::H(i, j),
                    Edge::V(i + 1, j),
                    Edge::H(i, j + 1),
                    Edge::V(i, j),
                ];
                let crossed: Vec<Edge> = (0..4)
                    .filter(|&k| above[k] != above[(k + 1) % 4])
                    .map(|k| edges[k])
                    .collect();
                match crossed.len() {
                    2 => segs.push([crossed[0], crossed[1]]),
                    4 => {
                        // Saddle: corners 0 and 2 on one side, 1 and 3 on the other. If the
                        // centre is on corner 0's side, 0 and 2 connect through it, so the line
                        // cuts off corners 1 and 3.
                        let centre = c.iter().sum::<f64>() / 4.0;
                        if (centre >= level) == above[0] {
                            segs.push([edges[0], edges[1]]); // around corner 1
                            segs.push([edges[2], edges[3]]); // around corner 3
                        } else {
                            segs.push([edges[3], edges[0]]); // around corner 0
                            segs.push([edges[1], edges[2]]); // around corner 2
                        }
                    }
                    _ => {}
                }
            }
        }
        segs
    }

    /// The contour lines z = level as polylines (open ones end on the grid's border or at a
    /// missing cell; closed ones repeat their first point at the end).
    pub fn contour(&self, level: f64) -> Vec<Vec<Point>> {
        let segs = self.edge_segments(level);
        let mut at: HashMap<Edge, Vec<usize>> = HashMap::new();
        for (k, s) in segs.iter().enumerate() {
            at.entry(s[0]).or_default().push(k);
            at.entry(s[1]).or_default().push(k);
        }
        let mut used = vec![false; segs.len()];
        let mut lines = Vec::new();
        // Open lines first (start at an edge with one segment), then closed loops.
        let mut starts: Vec<usize> = (0..segs.len())
            .filter(|&k| at[&segs[k][0]].len() == 1 || at[&segs[k][1]].len() == 1)
            .collect();
        starts.extend(0..segs.len());
        for k0 in starts {
            if used[k0] {
                continue;
            }
            used[k0] = true;
            let s = segs[k0];
            let (first, mut cur) = if at[&s[0]].len() == 1 {
                (s[0], s[1])
            } else {
                (s[1], s[0])
            };
            let mut edges = vec![first, cur];
            loop {
                let next = at[&cur].iter().copied().find(|&k| !used[k]);
                let Some(k) = next else { break };
                used[k] = true;
                cur = if segs[k][0] == cur {
                    segs[k][1]
                } else {
                    segs[k][0]
                };
                edges.push(cur);
            }
            // A level met exactly at a grid node gives the node twice (from two edges).
            let mut line: Vec<Point> = Vec::with_capacity(edges.len());
            for p in edges.iter().map(|&e| self.point(e, level)) {
                if line.last() != Some(&p) {
                    line.push(p);
                }
            }
            if line.len() >= 2 {
                lines.push(line);
            }
        }
        lines
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, f: impl Fn(f64, f64) -> f64) -> Field {
        let c: Vec<f64> = (0..n).map(|i| i as f64 / (n - 1) as f64).collect();
        let z = c
            .iter()
            .map(|&y| c.iter().map(|&x| f(x, y)).collect())
            .collect();
        Field::new(c.clone(), c, z).expect("field")
    }

    #[test]
    fn a_linear_field_has_its_exact_straight_boundary() {
        // F = 0.6 x + 0.2 y: the F = 0.3 boundary is the line x = (0.3 - 0.2 y) / 0.6.
        let f = grid(7, |x, y| 0.6 * x + 0.2 * y);
        let lines = f.contour(0.3);
        assert_eq!(lines.len(), 1, "{lines:?}");
        let line = &lines[0];
        assert_eq!(line.len(), 7, "one point per row: {line:?}");
        for &(x, y) in line {
            assert!((0.6 * x + 0.2 * y - 0.3).abs() < 1e-12, "({x}, {y})");
        }
        let ys: Vec<f64> = line.iter().map(|p| p.1).collect();
        assert!(ys.contains(&0.0) && ys.contains(&1.0), "{ys:?}");
    }

    #[test]
    fn a_circle_closes_and_stays_near_its_radius() {
        let f = grid(41, |x, y| ((x - 0.5).powi(2) + (y - 0.5).powi(2)).sqrt());
        let lines = f.contour(0.3);
        assert_eq!(lines.len(), 1);
        let line = &lines[0];
        assert_eq!(line.first(), line.last(), "closed loop");
        for &(x, y) in line {
            let r = ((x - 0.5).powi(2) + (y - 0.5).powi(2)).sqrt();
            assert!((r - 0.3).abs() < 2e-3, "r = {r}");
        }
    }

    #[test]
    fn missing_values_cut_the_line_and_interpolation_skips_them() {
        let mut f = grid(5, |x, _| x);
        f.z[2][1] = f64::NAN;
        assert_eq!(f.at(0.3, 0.55), None);
        assert!((f.at(0.8, 0.1).expect("inside") - 0.8).abs() < 1e-12);
        assert_eq!(f.at(1.5, 0.5), None);
        let lines = f.contour(0.375);
        assert_eq!(lines.len(), 2, "{lines:?}");
        let n: usize = lines.iter().map(Vec::len).sum();
        assert_eq!(n, 4, "{lines:?}");
    }

    #[test]
    fn saddles_connect_consistently() {
        let f = Field::new(
            vec![0.0, 1.0],
            vec![0.0, 1.0],
            vec![vec![1.0, 0.0], vec![0.0, 1.0]],
        )
        .expect("field");
        let lines = f.contour(0.5);
        assert_eq!(lines.len(), 2);
        assert!(lines.iter().all(|l| l.len() == 2));
    }
}
