//! The index of a variable: what factors name and [`crate::Values`] holds (a file of its own, below
//! both values and errors).

/// Index of a variable in [`crate::Values`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Key(pub usize);
