//! Ordered sets addressed by handles: the obstacles and the pins of a
//! [`crate::solver::Simulation`].
//!
//! A [`Handle`] names one element for as long as it is in its set and is
//! never given to another element afterwards, so a caller may keep it across
//! insertions and removals of other elements. The elements stay in the order
//! they were inserted (the solver visits them in that order, which keeps runs
//! reproducible bit for bit). Only the simulation inserts and removes, so it
//! can keep what it derives from a set (which vertex is pinned) in step with it.

use std::marker::PhantomData;

/// The name of one element of a [`Set<T>`].
pub struct Handle<T> {
    id: u64,
    of: PhantomData<fn() -> T>,
}

impl<T> Handle<T> {
    fn new(id: u64) -> Handle<T> {
        Handle {
            id,
            of: PhantomData,
        }
    }

    /// The handle's number (unique within its set, for logs).
    pub fn id(&self) -> u64 {
        self.id
    }
}

impl<T> Clone for Handle<T> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T> Copy for Handle<T> {}
impl<T> PartialEq for Handle<T> {
    fn eq(&self, o: &Self) -> bool {
        self.id == o.id
    }
}
impl<T> Eq for Handle<T> {}
impl<T> std::hash::Hash for Handle<T> {
    fn hash<H: std::hash::Hasher>(&self, h: &mut H) {
        self.id.hash(h)
    }
}
impl<T> std::fmt::Debug for Handle<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Handle({})", self.id)
    }
}

/// Elements in insertion order, each with its [`Handle`].
#[derive(Debug)]
pub struct Set<T> {
    items: Vec<T>,
    /// Handle ids of `items`, increasing (insertion order).
    ids: Vec<u64>,
    /// The id the next insertion gets.
    next: u64,
}

impl<T> Default for Set<T> {
    fn default() -> Self {
        Set {
            items: Vec::new(),
            ids: Vec::new(),
            next: 0,
        }
    }
}

/// Equal elements under equal handles.
impl<T: PartialEq> PartialEq for Set<T> {
    fn eq(&self, o: &Self) -> bool {
        self.items == o.items && self.ids == o.ids
    }
}

impl<T: Clone> Clone for Set<T> {
    fn clone(&self) -> Self {
        Set {
            items: self.items.clone(),
            ids: self.ids.clone(),
            next: self.next,
        }
    }
}

impl<T> Set<T> {
    /// An empty set.
    pub fn new() -> Set<T> {
        Set::default()
    }

    /// The elements in insertion order, to change in place.
    pub fn iter_mut(&mut self) -> std::slice::IterMut<'_, T> {
        self.items.iter_mut()
    }

    /// The elements in insertion order, as a slice.
    pub fn as_slice(&self) -> &[T] {
        &self.items
    }

    /// Each element with its handle, in insertion order.
    pub fn with_handles(&self) -> impl Iterator<Item = (Handle<T>, &T)> {
        self.ids.iter().map(|&id| Handle::new(id)).zip(&self.items)
    }

    /// Where `h`'s element is in [`Set::as_slice`], if it is in the set.
    pub fn position(&self, h: Handle<T>) -> Option<usize> {
        self.ids.binary_search(&h.id).ok()
    }

    /// The element `h` names, if still there.
    pub fn get(&self, h: Handle<T>) -> Option<&T> {
        self.position(h).map(|k| &self.items[k])
    }

    /// Whether `h` names an element of the set.
    pub fn contains(&self, h: Handle<T>) -> bool {
        self.position(h).is_some()
    }

    /// The handle of the first element that satisfies `f`.
    pub fn find(&self, f: impl Fn(&T) -> bool) -> Option<Handle<T>> {
        self.with_handles().find(|(_, t)| f(t)).map(|(h, _)| h)
    }

    /// Adds `t` at the end; its handle.
    pub fn insert(&mut self, t: T) -> Handle<T> {
        let id = self.next;
        self.next += 1;
        self.items.push(t);
        self.ids.push(id);
        Handle::new(id)
    }

    /// Takes `h`'s element out (the others keep their order and handles).
    pub fn remove(&mut self, h: Handle<T>) -> Option<T> {
        let k = self.position(h)?;
        self.ids.remove(k);
        Some(self.items.remove(k))
    }

    /// The element `h` names, to change.
    pub fn get_mut(&mut self, h: Handle<T>) -> Option<&mut T> {
        self.position(h).map(|k| &mut self.items[k])
    }

    /// Keeps the elements for which `keep` is true.
    pub fn retain(&mut self, mut keep: impl FnMut(&T) -> bool) {
        let mut k = 0;
        let ids = &mut self.ids;
        self.items.retain(|t| {
            let kept = keep(t);
            if !kept {
                ids.remove(k);
            } else {
                k += 1;
            }
            kept
        });
    }

    /// Replaces the elements by `other`'s, handles included. Handles this
    /// set gave out since `other` was taken from it are not given again.
    pub fn replace(&mut self, other: Set<T>) {
        let next = self.next.max(other.next);
        *self = other;
        self.next = next;
    }
}

/// Read as a slice of the elements in insertion order.
impl<T> std::ops::Deref for Set<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        &self.items
    }
}

impl<T> FromIterator<T> for Set<T> {
    fn from_iter<I: IntoIterator<Item = T>>(it: I) -> Self {
        let mut s = Set::new();
        for t in it {
            s.insert(t);
        }
        s
    }
}

impl<'a, T> IntoIterator for &'a Set<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.items.iter()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn handles_survive_removals_and_are_never_reused() {
        let mut s: Set<&str> = ["a", "b", "c"].into_iter().collect();
        let h: Vec<Handle<&str>> = s.with_handles().map(|(h, _)| h).collect();
        assert_eq!(s.remove(h[1]), Some("b"));
        assert_eq!(s.get(h[0]), Some(&"a"));
        assert_eq!(s.get(h[2]), Some(&"c"));
        assert_eq!(s.get(h[1]), None);
        assert_eq!(s.as_slice(), &["a", "c"]);
        let d = s.insert("d");
        assert!(h.iter().all(|&x| x != d));
        assert_eq!(s.as_slice(), &["a", "c", "d"]);
        s.retain(|t| *t != "c");
        assert_eq!(s.as_slice(), &["a", "d"]);
        assert_eq!(s.position(d), Some(1));
        assert_eq!(s.get(h[2]), None);
        // a snapshot put back keeps its handles; newer ones stay unused
        let snap = s.clone();
        let e = s.insert("e");
        s.replace(snap);
        assert_eq!(s.get(h[0]), Some(&"a"));
        assert_eq!(s.get(e), None);
        let f = s.insert("f");
        assert_ne!(f, e);
        assert_eq!(s.find(|t| *t == "f"), Some(f));
    }
}
