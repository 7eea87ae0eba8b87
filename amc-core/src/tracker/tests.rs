//! Unit tests of the tracker.
