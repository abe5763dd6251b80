//! Errors of the query layer.

/// What went wrong while preparing or answering a query.
#[derive(Debug, thiserror::Error)]
pub enum QueryError {
    #[error("{path}: {reason}")]
    Embeddings { path: String, reason: String },
    #[error("language decoder: {0}")]
    Decoder(String),
    #[error("query: {0}")]
    Invalid(String),
    #[error(transparent)]
    Format(#[from] dlgs::Error),
    #[error("{path}: {reason}")]
    Io { path: String, reason: String },
}

pub type Result<T> = std::result::Result<T, QueryError>;
