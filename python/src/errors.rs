//! Typed errors as Python exceptions: `DlgsError` and one subclass per kind of
//! [`dlgs::Error`], each carrying `kind`, `name` (the spec-level fault, e.g. `PayloadCrc`),
//! `offset` (byte in the file, or `None`) and `message`.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    _dlgs,
    DlgsError,
    PyException,
    "Base of every dlgs error: attributes kind, name, offset (int or None), message."
);
create_exception!(
    _dlgs,
    FormatError,
    DlgsError,
    "The bytes break the .dlgs spec (or a foreign splat file is malformed)."
);
create_exception!(
    _dlgs,
    LimitError,
    DlgsError,
    "A declared size passes the reader's resource limits."
);
create_exception!(
    _dlgs,
    DlgsIoError,
    DlgsError,
    "The operating system failed a read or write."
);
create_exception!(
    _dlgs,
    RequestError,
    DlgsError,
    "A bad request or parameter (time out of range, bad camera, ...)."
);
create_exception!(
    _dlgs,
    InputError,
    DlgsError,
    "Data the encoder refuses to write (shapes, non-finite values, ...)."
);
create_exception!(
    _dlgs,
    NoHevcDecoderError,
    DlgsError,
    "HEVC time features in a module built without the `hevc` feature."
);

/// Register the exception classes on the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("DlgsError", py.get_type::<DlgsError>())?;
    m.add("FormatError", py.get_type::<FormatError>())?;
    m.add("LimitError", py.get_type::<LimitError>())?;
    m.add("DlgsIoError", py.get_type::<DlgsIoError>())?;
    m.add("RequestError", py.get_type::<RequestError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("NoHevcDecoderError", py.get_type::<NoHevcDecoderError>())?;
    Ok(())
}

/// Build the exception `err` with its attributes set.
fn with_attrs(err: PyErr, kind: &str, name: &str, offset: Option<u64>, message: &str) -> PyErr {
    Python::with_gil(|py| {
        let v = err.value(py);
        // Setting attributes on a fresh exception instance cannot fail in practice; if it did,
        // the exception still carries its message.
        let _ = v.setattr("kind", kind);
        let _ = v.setattr("name", name);
        let _ = v.setattr("offset", offset);
        let _ = v.setattr("message", message);
    });
    err
}

/// A [`dlgs::Error`] as the matching Python exception.
pub fn to_py(e: dlgs::Error) -> PyErr {
    let msg = e.to_string();
    let offset = e.offset();
    let (err, kind, name): (PyErr, &str, String) = match &e {
        dlgs::Error::Format(f) => (
            FormatError::new_err(msg.clone()),
            "Format",
            f.kind.name().to_string(),
        ),
        dlgs::Error::Limit(_) => (LimitError::new_err(msg.clone()), "Limit", "Limit".into()),
        dlgs::Error::Io(_) => (DlgsIoError::new_err(msg.clone()), "Io", "Io".into()),
        dlgs::Error::Request(_) => (
            RequestError::new_err(msg.clone()),
            "Request",
            "Request".into(),
        ),
        dlgs::Error::Input(_) => (InputError::new_err(msg.clone()), "Input", "Input".into()),
        dlgs::Error::NoHevcDecoder => (
            NoHevcDecoderError::new_err(msg.clone()),
            "NoHevcDecoder",
            "NoHevcDecoder".into(),
        ),
        _ => (DlgsError::new_err(msg.clone()), "Other", "Other".into()),
    };
    with_attrs(err, kind, &name, offset, &msg)
}

/// A bad argument from Python (shape, name, range): a `RequestError`.
pub fn request(message: impl Into<String>) -> PyErr {
    let m = message.into();
    with_attrs(
        RequestError::new_err(m.clone()),
        "Request",
        "Request",
        None,
        &m,
    )
}

/// Data the encoder refuses (from Python arrays): an `InputError`.
pub fn input(message: impl Into<String>) -> PyErr {
    let m = message.into();
    with_attrs(InputError::new_err(m.clone()), "Input", "Input", None, &m)
}

/// Errors of the renderer and the query crate (their own types): a `RequestError` with the
/// crate's message.
pub fn other(e: impl std::fmt::Display) -> PyErr {
    request(e.to_string())
}

pub type Res<T> = Result<T, PyErr>;

/// `?` on [`dlgs::Result`].
pub trait IntoPy<T> {
    fn py_err(self) -> Res<T>;
}

impl<T> IntoPy<T> for dlgs::Result<T> {
    fn py_err(self) -> Res<T> {
        self.map_err(to_py)
    }
}
