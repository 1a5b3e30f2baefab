//! Training logs: TensorBoard event files and a CSV, written together.

pub mod csv;
pub mod tensorboard;

pub use self::csv::CsvLogger;
pub use tensorboard::{ScalarEvent, TensorBoardWriter, read_scalars};
