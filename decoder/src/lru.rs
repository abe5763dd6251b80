//! A small least-recently-used cache keyed by GOP index, for the decoder's state and GOP
//! caches. A handful of entries at most, so a linear scan beats any map.

pub(crate) struct GopLru<T: Clone> {
    capacity: usize,
    /// A GOP evicted only when it is the sole entry the capacity allows (GOP 0 for the state
    /// cache: every parallel-mode GOP's reference).
    spared: Option<u32>,
    clock: u64,
    entries: Vec<(u32, T, u64)>,
}

impl<T: Clone> GopLru<T> {
    pub(crate) fn new(capacity: usize, spared: Option<u32>) -> Self {
        GopLru {
            capacity,
            spared,
            clock: 0,
            entries: Vec::new(),
        }
    }

    /// Change the capacity; drops every entry.
    pub(crate) fn reset(&mut self, capacity: usize) {
        self.capacity = capacity;
        self.entries.clear();
    }

    /// Drop every entry, keeping the capacity.
    pub(crate) fn clear(&mut self) {
        self.entries.clear();
    }

    pub(crate) fn get(&mut self, g: u32) -> Option<T> {
        self.clock += 1;
        let now = self.clock;
        self.entries.iter_mut().find(|e| e.0 == g).map(|e| {
            e.2 = now;
            e.1.clone()
        })
    }

    /// Whether `g` is held (not counted as a use).
    pub(crate) fn contains(&self, g: u32) -> bool {
        self.entries.iter().any(|e| e.0 == g)
    }

    pub(crate) fn insert(&mut self, g: u32, v: T) {
        if self.capacity == 0 || self.entries.iter().any(|e| e.0 == g) {
            return;
        }
        self.clock += 1;
        if self.entries.len() >= self.capacity {
            let spared = if self.capacity == 1 {
                None
            } else {
                self.spared
            };
            if let Some(i) = self
                .entries
                .iter()
                .enumerate()
                .filter(|(_, e)| Some(e.0) != spared)
                .min_by_key(|(_, e)| e.2)
                .map(|(i, _)| i)
            {
                self.entries.swap_remove(i);
            }
        }
        self.entries.push((g, v, self.clock));
    }

    /// The cached GOP indices, ascending.
    pub(crate) fn keys(&self) -> Vec<u32> {
        let mut k: Vec<u32> = self.entries.iter().map(|e| e.0).collect();
        k.sort_unstable();
        k
    }
}

#[cfg(test)]
mod tests {
    use super::GopLru;

    #[test]
    fn evicts_the_least_recently_used_but_the_spared_gop() {
        let mut c = GopLru::new(3, Some(0));
        for g in [0, 1, 2] {
            c.insert(g, g);
        }
        assert_eq!(c.get(1), Some(1));
        c.insert(3, 3); // 0 is older than 2 but spared
        assert_eq!(c.keys(), vec![0, 1, 3]);
        c.insert(4, 4); // 1 was used before 3 was inserted
        assert_eq!(c.keys(), vec![0, 3, 4]);
    }

    #[test]
    fn capacity_one_keeps_the_newest_and_zero_keeps_nothing() {
        let mut c = GopLru::new(1, Some(0));
        c.insert(0, 'a');
        c.insert(5, 'b');
        assert_eq!(c.keys(), vec![5]);
        c.reset(0);
        c.insert(2, 'c');
        assert!(c.keys().is_empty() && c.get(2).is_none());
    }
}
