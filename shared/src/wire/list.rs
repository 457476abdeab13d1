//! [`List`]: a fixed-capacity list that travels as a postcard sequence.

use core::fmt;
use core::marker::PhantomData;

use serde::de::{self, SeqAccess, Visitor};
use serde::ser::SerializeSeq;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::WireError;

/// Up to `N` items stored inline (no heap).
///
/// On the wire a `List` is a postcard sequence: `varint(len)` followed by
/// `len` items. Decoding a sequence longer than `N` fails (the frame counts
/// as a decode error) before any item past the capacity is read.
#[derive(Clone, Copy)]
pub struct List<T, const N: usize> {
    len: usize,
    items: [T; N],
}

impl<T: Copy + Default, const N: usize> Default for List<T, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Copy + Default, const N: usize> List<T, N> {
    /// The empty list.
    #[must_use]
    pub fn new() -> Self {
        Self {
            len: 0,
            items: [T::default(); N],
        }
    }

    /// A list holding a copy of `items`.
    ///
    /// # Errors
    /// [`WireError::BufferFull`] if `items.len() > N`.
    pub fn from_slice(items: &[T]) -> Result<Self, WireError> {
        let mut list = Self::new();
        for &item in items {
            list.push(item)?;
        }
        Ok(list)
    }

    /// Appends `item`.
    ///
    /// # Errors
    /// [`WireError::BufferFull`] if the list is full.
    pub fn push(&mut self, item: T) -> Result<(), WireError> {
        let slot = self.items.get_mut(self.len).ok_or(WireError::BufferFull)?;
        *slot = item;
        self.len = self.len.saturating_add(1);
        Ok(())
    }
}

impl<T, const N: usize> List<T, N> {
    /// The slot the next item would take (its old contents), if the list
    /// is not full: fill it in place, then [`List::commit`] it.
    pub(crate) fn next_slot(&mut self) -> Option<&mut T> {
        self.items.get_mut(self.len)
    }

    /// Keeps the slot [`List::next_slot`] gave as the last item.
    pub(crate) fn commit(&mut self) {
        self.len = self.len.saturating_add(1).min(N);
    }

    /// The items, in order.
    #[must_use]
    pub fn as_slice(&self) -> &[T] {
        self.items.get(..self.len).unwrap_or(&[])
    }

    /// Number of items.
    #[must_use]
    pub fn len(&self) -> usize {
        self.len
    }

    /// True if the list holds no item.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The capacity `N`.
    #[must_use]
    pub const fn capacity(&self) -> usize {
        N
    }

    /// Removes every item (in place: cheaper than assigning a new list,
    /// which writes the whole capacity).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Iterates over the items.
    pub fn iter(&self) -> core::slice::Iter<'_, T> {
        self.as_slice().iter()
    }
}

impl<'a, T, const N: usize> IntoIterator for &'a List<T, N> {
    type Item = &'a T;
    type IntoIter = core::slice::Iter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<T: PartialEq, const N: usize> PartialEq for List<T, N> {
    fn eq(&self, other: &Self) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl<T: fmt::Debug, const N: usize> fmt::Debug for List<T, N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.as_slice()).finish()
    }
}

impl<T: Serialize, const N: usize> Serialize for List<T, N> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let items = self.as_slice();
        let mut seq = serializer.serialize_seq(Some(items.len()))?;
        for item in items {
            seq.serialize_element(item)?;
        }
        seq.end()
    }
}

struct ListVisitor<T, const N: usize>(PhantomData<T>);

impl<'de, T, const N: usize> Visitor<'de> for ListVisitor<T, N>
where
    T: Deserialize<'de> + Copy + Default,
{
    type Value = List<T, N>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "a sequence of at most {N} items")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
        if seq.size_hint().is_some_and(|n| n > N) {
            return Err(de::Error::custom("list over capacity"));
        }
        let mut list = List::new();
        while let Some(item) = seq.next_element()? {
            list.push(item)
                .map_err(|_| de::Error::custom("list over capacity"))?;
        }
        Ok(list)
    }
}

impl<'de, T, const N: usize> Deserialize<'de> for List<T, N>
where
    T: Deserialize<'de> + Copy + Default,
{
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        deserializer.deserialize_seq(ListVisitor::<T, N>(PhantomData))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_until_full() {
        let mut l = List::<u8, 2>::new();
        assert!(l.is_empty());
        l.push(7).unwrap();
        l.push(9).unwrap();
        assert_eq!(l.push(1), Err(WireError::BufferFull));
        assert_eq!(l.as_slice(), &[7, 9]);
        assert_eq!(l.len(), 2);
        assert_eq!(l.capacity(), 2);
        l.clear();
        assert!(l.is_empty());
        l.push(3).unwrap();
        assert_eq!(l.as_slice(), &[3]);
        assert_eq!(
            List::<u8, 2>::from_slice(&[1, 2, 3]),
            Err(WireError::BufferFull)
        );
    }

    #[test]
    fn postcard_layout_is_len_then_items() {
        let l = List::<u16, 4>::from_slice(&[1, 300]).unwrap();
        let mut buf = [0u8; 16];
        let used = postcard::to_slice(&l, &mut buf).unwrap();
        // varint(2), varint(1), varint(300) = AC 02.
        assert_eq!(used, &[0x02, 0x01, 0xAC, 0x02]);
        let back: List<u16, 4> = postcard::from_bytes(used).unwrap();
        assert_eq!(back, l);
        // Three items do not fit a List<u16, 2>.
        assert!(postcard::from_bytes::<List<u16, 2>>(&[0x03, 1, 2, 3]).is_err());
        // A length prefix larger than the data is rejected, not over-read.
        assert!(postcard::from_bytes::<List<u16, 4>>(&[0x04, 1, 2]).is_err());
    }
}
