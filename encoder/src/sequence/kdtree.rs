//! An exact k-nearest-neighbour search over points of `D` dimensions (a k-d tree of
//! median splits), for matching Gaussians in a joint space of position and attributes.

/// Squared Euclidean distance.
fn dist2<const D: usize>(a: &[f32; D], b: &[f32; D]) -> f32 {
    let mut s = 0.0;
    for d in 0..D {
        let t = a[d] - b[d];
        s += t * t;
    }
    s
}

/// Points are stored in tree order; `index` maps back to the caller's numbering.
pub struct KdTree<const D: usize> {
    points: Vec<[f32; D]>,
    index: Vec<u32>,
    /// Split dimension of each node (the node is the middle of its range); `u8::MAX` on leaves.
    split: Vec<u8>,
}

const LEAF: usize = 8;

impl<const D: usize> KdTree<D> {
    pub fn new(points: &[[f32; D]]) -> Self {
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        let mut split = vec![u8::MAX; points.len()];
        build(points, &mut order, 0, &mut split);
        KdTree {
            points: order.iter().map(|&i| points[i as usize]).collect(),
            index: order,
            split,
        }
    }

    /// The `k` nearest points to `q` as (caller index, squared distance), nearest first; ties
    /// go to the lower index.
    pub fn nearest(&self, q: &[f32; D], k: usize) -> Vec<(u32, f32)> {
        let mut best: Vec<(f32, u32)> = Vec::with_capacity(k + 1);
        if k > 0 {
            self.search(q, k, 0, self.points.len(), &mut best);
        }
        best.into_iter().map(|(d, i)| (i, d)).collect()
    }

    fn search(&self, q: &[f32; D], k: usize, lo: usize, hi: usize, best: &mut Vec<(f32, u32)>) {
        if hi - lo <= LEAF || self.split[lo + (hi - lo) / 2] == u8::MAX {
            for p in lo..hi {
                insert(best, k, (dist2(q, &self.points[p]), self.index[p]));
            }
            return;
        }
        let mid = lo + (hi - lo) / 2;
        let d = self.split[mid] as usize;
        insert(best, k, (dist2(q, &self.points[mid]), self.index[mid]));
        let diff = q[d] - self.points[mid][d];
        let (near, far) = if diff < 0.0 {
            ((lo, mid), (mid + 1, hi))
        } else {
            ((mid + 1, hi), (lo, mid))
        };
        self.search(q, k, near.0, near.1, best);
        if best.len() < k || diff * diff <= best[best.len() - 1].0 {
            self.search(q, k, far.0, far.1, best);
        }
    }
}

fn insert(best: &mut Vec<(f32, u32)>, k: usize, c: (f32, u32)) {
    if best.len() == k && (c.0, c.1) >= (best[k - 1].0, best[k - 1].1) {
        return;
    }
    let at = best.partition_point(|b| (b.0, b.1) < (c.0, c.1));
    best.insert(at, c);
    best.truncate(k);
}

fn build<const D: usize>(points: &[[f32; D]], order: &mut [u32], base: usize, split: &mut [u8]) {
    if order.len() <= LEAF {
        return;
    }
    // Split on the widest dimension at the median.
    let mut lo = [f32::INFINITY; D];
    let mut hi = [f32::NEG_INFINITY; D];
    for &i in order.iter() {
        for d in 0..D {
            lo[d] = lo[d].min(points[i as usize][d]);
            hi[d] = hi[d].max(points[i as usize][d]);
        }
    }
    let d = (0..D)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(0);
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| {
        points[a as usize][d]
            .total_cmp(&points[b as usize][d])
            .then(a.cmp(&b))
    });
    split[base + mid] = d as u8;
    let (left, right) = order.split_at_mut(mid);
    build(points, left, base, split);
    build(points, &mut right[1..], base + mid + 1, split);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_agrees_with_brute_force() {
        let mut rng = fastrand::Rng::with_seed(3);
        let pts: Vec<[f32; 5]> = (0..2000)
            .map(|_| std::array::from_fn(|_| rng.f32()))
            .collect();
        let tree = KdTree::new(&pts);
        for _ in 0..200 {
            let q: [f32; 5] = std::array::from_fn(|_| rng.f32());
            let got = tree.nearest(&q, 4);
            let mut all: Vec<(f32, u32)> = pts
                .iter()
                .enumerate()
                .map(|(i, p)| (dist2(&q, p), i as u32))
                .collect();
            all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let want: Vec<(u32, f32)> = all[..4].iter().map(|&(d, i)| (i, d)).collect();
            assert_eq!(got, want);
        }
        assert!(KdTree::<2>::new(&[]).nearest(&[0.0, 0.0], 3).is_empty());
    }
}
