//! Tables built once per process and shared: the quadrature rules, the exponentiation
//! grids, the OL fit, the tripling tensor and each Phong lobe's eps, which every kernel
//! of the same order and setting needs again (a sweep's settings, the viewer's frames, a
//! benchmark's repeats). Each table is a pure function of its key, so a table shared is
//! the table built again, bit for bit. What is held stays small: the keys are orders (at
//! most 8), methods and the scenes' lobes, and the largest table, order 8's fine
//! quadrature grid (8,192 nodes of 64 coefficients), is 4 MB.

use std::collections::HashMap;
use std::hash::Hash;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

/// Tables of type `V` by key, built at their first request.
pub struct Memo<K, V> {
    tables: OnceLock<Mutex<HashMap<K, Arc<V>>>>,
}

impl<K: Hash + Eq, V> Memo<K, V> {
    pub const fn new() -> Self {
        Self { tables: OnceLock::new() }
    }

    /// The table of `key`, built by `build` where none is held. It is built outside the
    /// lock, so a slow table does not hold up others; where two threads build the same
    /// one together, the first kept is the one both get.
    pub fn get_or_build(&self, key: K, build: impl FnOnce() -> V) -> Arc<V> {
        if let Some(table) = self.lock().get(&key) {
            return table.clone();
        }
        let built = Arc::new(build());
        self.lock().entry(key).or_insert(built).clone()
    }

    /// A panic while the lock was held (in a caller's thread) leaves the map whole: it is
    /// only ever read or given a finished table.
    fn lock(&self) -> MutexGuard<'_, HashMap<K, Arc<V>>> {
        self.tables.get_or_init(Default::default).lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl<K: Hash + Eq, V> Default for Memo<K, V> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_is_built_once_per_key() {
        let memo: Memo<u32, Vec<u32>> = Memo::new();
        let mut builds = 0;
        let first = memo.get_or_build(3, || {
            builds += 1;
            vec![3; 3]
        });
        let again = memo.get_or_build(3, || {
            builds += 1;
            vec![0]
        });
        let other = memo.get_or_build(4, || {
            builds += 1;
            vec![4; 4]
        });
        assert_eq!(builds, 2);
        assert!(Arc::ptr_eq(&first, &again));
        assert_eq!((first.as_slice(), other.as_slice()), (&[3, 3, 3][..], &[4, 4, 4, 4][..]));
    }
}
