//! Many short lists in two arrays (compressed sparse rows): list `i` is
//! `items[offsets[i]..offsets[i + 1]]`. The per-receiver and per-triangle
//! lists of the hierarchy and of the visible sets are read in the
//! per-receiver loop, where one contiguous array beats a `Vec` per list.

/// Lists of `T`, one after another.
#[derive(Clone, Debug)]
pub(crate) struct Csr<T> {
    /// Starts at 0; one more than there are lists.
    offsets: Vec<u32>,
    items: Vec<T>,
}

impl<T> Default for Csr<T> {
    fn default() -> Self {
        Csr {
            offsets: vec![0],
            items: Vec::new(),
        }
    }
}

impl<T: Copy> Csr<T> {
    /// The lists of `lists`, in order.
    pub(crate) fn from_lists<L: AsRef<[T]>>(lists: impl IntoIterator<Item = L>) -> Csr<T> {
        let mut csr = Csr::default();
        for list in lists {
            csr.push(list.as_ref());
        }
        csr
    }

    /// Appends one list.
    pub(crate) fn push(&mut self, list: &[T]) {
        self.items.extend_from_slice(list);
        let end = u32::try_from(self.items.len()).expect("fewer than 2³² listed items");
        self.offsets.push(end);
    }
}

impl<T> Csr<T> {
    /// List `i`.
    #[inline(always)]
    pub(crate) fn of(&self, i: usize) -> &[T] {
        &self.items[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_come_back_in_order_empty_ones_included() {
        let mut csr = Csr::from_lists([vec![1, 2], vec![], vec![3]]);
        csr.push(&[4, 5]);
        assert_eq!(csr.of(0), &[1, 2]);
        assert!(csr.of(1).is_empty());
        assert_eq!(csr.of(2), &[3]);
        assert_eq!(csr.of(3), &[4, 5]);
    }
}
