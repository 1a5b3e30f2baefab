//! Training logs: TensorBoard event files and a CSV, written together.

pub mod csv;
pub mod tensorboard;

pub use self::csv::{CsvLogger, ProgressError, ProgressLog};
pub use tensorboard::{ScalarEvent, TensorBoardWriter, read_scalars};
