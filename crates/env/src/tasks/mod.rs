//! The registered tasks. An arm task is one small type implementing [`crate::arm::Task`] on the
//! shared arm environment; the classic-control tasks are plain environments.

pub mod classic;
pub mod grasp;
pub mod pick_place;
pub mod sort;

pub use grasp::GraspFlags;
pub use pick_place::PlaceFlags;
pub use sort::SortFlags;
