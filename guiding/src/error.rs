//! The one error type of the crate: invalid training samples, invalid settings, and fields
//! that cannot be read back.

/// Everything that can go wrong when training, saving or loading a field.
#[derive(Debug, thiserror::Error)]
pub enum GuidingError {
    /// A training sample was rejected. Bad samples are refused rather than absorbed, because a
    /// single NaN would poison every statistic of its region.
    #[error("training sample {index} is invalid: {reason}")]
    InvalidSample {
        /// Index of the offending sample in the slice passed to `Field::update`.
        index: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// A `FieldConfig` setting is out of range.
    #[error("invalid field configuration: {0}")]
    InvalidConfig(String),
    /// A mixture was built from lobes that are not usable (NaN, negative weights, ...).
    #[error("invalid mixture: {0}")]
    InvalidMixture(String),
    /// Reading or writing a saved field failed.
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
    /// The data does not start with the magic bytes of a saved guiding field.
    #[error("not a zerovar guiding field (bad magic bytes)")]
    BadMagic,
    /// The saved field was written by another format version.
    #[error(
        "guiding field format version {found} is not supported (this build reads {expected}); \
         train the field again"
    )]
    Version {
        /// The version in the file.
        found: u32,
        /// The version this build reads and writes.
        expected: u32,
    },
    /// The saved field is truncated or corrupt.
    #[error("corrupt guiding field: {0}")]
    Decode(String),
}
