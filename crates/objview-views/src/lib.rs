//! View sets and view spaces.
