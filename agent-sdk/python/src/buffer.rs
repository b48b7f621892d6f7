//! Memory the Rust side owns, exported to Python through the buffer protocol: the N-d
//! layout of an image, and filling a `Py_buffer` from it. Read-only for an agent's
//! received frames, writable for a host's loaned frames; the exporting object keeps the
//! layout (its `shape` and `strides` arrays are pointed to by every export).

use std::ffi::{CStr, c_int, c_void};

use pyo3::exceptions::PyBufferError;
use pyo3::ffi;
use pyo3::prelude::*;
use vrsync_bridge::PixelFormat;

/// The shape of an up to 3-dimensional array of one item type.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    format: &'static CStr,
    itemsize: isize,
    ndim: c_int,
    shape: [isize; 3],
    strides: [isize; 3],
}

impl Layout {
    /// An image: H×W×3 or H×W×4 `uint8` (rgb8, rgba8), H×W `uint8` (gray8) or H×W
    /// `float32` (depth32f), rows `stride` bytes apart.
    pub(crate) fn image(format: PixelFormat, width: u32, height: u32, stride: usize) -> Self {
        let (w, h, stride) = (width as isize, height as isize, stride as isize);
        let (format, itemsize, ndim, shape, strides): (&'static CStr, isize, c_int, _, _) =
            match format {
                PixelFormat::Rgb8 => (c"B", 1, 3, [h, w, 3], [stride, 3, 1]),
                PixelFormat::Rgba8 => (c"B", 1, 3, [h, w, 4], [stride, 4, 1]),
                PixelFormat::Gray8 => (c"B", 1, 2, [h, w, 0], [stride, 1, 0]),
                PixelFormat::Depth32f => (c"f", 4, 2, [h, w, 0], [stride, 4, 0]),
            };
        Self {
            format,
            itemsize,
            ndim,
            shape,
            strides,
        }
    }

    /// A vector of `len` `float32`.
    pub(crate) fn vector(len: usize) -> Self {
        Self {
            format: c"f",
            itemsize: 4,
            ndim: 1,
            shape: [len as isize, 0, 0],
            strides: [4, 0, 0],
        }
    }

    /// Whether the rows follow each other without padding.
    fn contiguous(&self) -> bool {
        self.ndim == 1 || self.strides[0] == self.shape[1] * self.itemsize * self.shape[2].max(1)
    }
}

/// Fills `view` with the `len` bytes at `ptr`, shaped by `layout`, for `owner`.
/// `readonly`: `Some(why)` exports read-only and refuses a writable request with `why`;
/// `None` exports writable.
///
/// # Safety
/// `view` is null or a `Py_buffer` to fill (as the buffer protocol hands it over);
/// `ptr..ptr + len` stays valid (and, when exported writable, writable by nobody else)
/// as long as `owner` lives; `layout` lives inside `owner` and describes at most `len`
/// bytes.
pub(crate) unsafe fn fill(
    view: *mut ffi::Py_buffer,
    flags: c_int,
    ptr: *mut u8,
    len: usize,
    layout: &Layout,
    readonly: Option<&str>,
    owner: Bound<'_, PyAny>,
) -> PyResult<()> {
    if view.is_null() {
        return Err(PyBufferError::new_err("null Py_buffer"));
    }
    if let Some(why) = readonly
        && flags & ffi::PyBUF_WRITABLE == ffi::PyBUF_WRITABLE
    {
        return Err(PyBufferError::new_err(why.to_owned()));
    }
    if flags & ffi::PyBUF_STRIDES != ffi::PyBUF_STRIDES && !layout.contiguous() {
        return Err(PyBufferError::new_err(
            "this image has padded rows: request a strided buffer (numpy does)",
        ));
    }
    // SAFETY: `view` is valid (checked non-null, guaranteed by the protocol). The pointers
    // stored in it (`buf`, `format`, `shape`, `strides`) point into memory that the caller
    // keeps valid as long as `owner` lives, and into `layout` (inside `owner`), which
    // `obj` keeps alive until the export is released.
    unsafe {
        (*view).buf = ptr.cast::<c_void>();
        (*view).len = len as isize;
        (*view).readonly = c_int::from(readonly.is_some());
        (*view).itemsize = layout.itemsize;
        (*view).format = if flags & ffi::PyBUF_FORMAT == ffi::PyBUF_FORMAT {
            layout.format.as_ptr().cast_mut()
        } else {
            std::ptr::null_mut()
        };
        if flags & ffi::PyBUF_ND == ffi::PyBUF_ND {
            (*view).ndim = layout.ndim;
            (*view).shape = layout.shape.as_ptr().cast_mut();
        } else {
            // A simple request: one dimension of `len` bytes.
            (*view).ndim = 1;
            (*view).itemsize = 1;
            (*view).shape = std::ptr::null_mut();
        }
        (*view).strides = if flags & ffi::PyBUF_STRIDES == ffi::PyBUF_STRIDES {
            layout.strides.as_ptr().cast_mut()
        } else {
            std::ptr::null_mut()
        };
        (*view).suboffsets = std::ptr::null_mut();
        (*view).internal = std::ptr::null_mut();
        (*view).obj = owner.into_ptr();
    }
    Ok(())
}

/// `numpy.asarray(obj)`: an array viewing `obj`'s exported buffer (no copy).
pub(crate) fn as_array<'py>(obj: Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    use pyo3::sync::PyOnceLock;
    static ASARRAY: PyOnceLock<Py<PyAny>> = PyOnceLock::new();
    let py = obj.py();
    let asarray = ASARRAY.get_or_try_init(py, || {
        Ok::<_, PyErr>(py.import("numpy")?.getattr("asarray")?.unbind())
    })?;
    asarray.bind(py).call1((obj,))
}
