//! Memory the Rust side owns, shown to Python as numpy arrays without a copy: the N-d
//! layout of an image or a vector, and an array made over it by numpy's C API, whose
//! `base` is a Python object that keeps the memory valid. Read-only for an agent's
//! received frames, writable for a host's loaned frames.
//!
//! The array is made directly (`PyArray_NewFromDescr` + `PyArray_SetBaseObject`), not
//! through the buffer protocol (`numpy.asarray` of an exporter): that way made a
//! memoryview, parsed a PEP 3118 format string and made the array, ~3× the work per view
//! (the Python host makes one per image per agent per cycle).

use std::ffi::{c_int, c_void};

use numpy::npyffi::{self, NPY_ARRAY_WRITEABLE, PY_ARRAY_API, npy_intp};
use numpy::{Element, PyArrayDescrMethods};
use pyo3::prelude::*;
use vrsync_bridge::PixelFormat;

/// The item type of an array.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Item {
    U8,
    F32,
}

/// The shape of an up to 4-dimensional array of one item type; strides in bytes.
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    item: Item,
    ndim: c_int,
    shape: [npy_intp; 4],
    strides: [npy_intp; 4],
}

impl Layout {
    /// An image: H×W×3 or H×W×4 `uint8` (rgb8, rgba8), H×W `uint8` (gray8) or H×W
    /// `float32` (depth32f), rows `stride` bytes apart.
    pub(crate) fn image(format: PixelFormat, width: u32, height: u32, stride: usize) -> Self {
        let (w, h, stride) = (width as npy_intp, height as npy_intp, stride as npy_intp);
        let (item, ndim, shape, strides) = match format {
            PixelFormat::Rgb8 => (Item::U8, 3, [h, w, 3, 0], [stride, 3, 1, 0]),
            PixelFormat::Rgba8 => (Item::U8, 3, [h, w, 4, 0], [stride, 4, 1, 0]),
            PixelFormat::Gray8 => (Item::U8, 2, [h, w, 0, 0], [stride, 1, 0, 0]),
            PixelFormat::Depth32f => (Item::F32, 2, [h, w, 0, 0], [stride, 4, 0, 0]),
        };
        Self {
            item,
            ndim,
            shape,
            strides,
        }
    }

    /// `n` images of [`Layout::image`]'s shape, `block` bytes from one to the next:
    /// `(n, H, W[, C])`.
    pub(crate) fn stacked_image(
        format: PixelFormat,
        width: u32,
        height: u32,
        stride: usize,
        n: usize,
        block: usize,
    ) -> Self {
        let one = Self::image(format, width, height, stride);
        let mut shape = [n as npy_intp, 0, 0, 0];
        let mut strides = [block as npy_intp, 0, 0, 0];
        shape[1..].copy_from_slice(&one.shape[..3]);
        strides[1..].copy_from_slice(&one.strides[..3]);
        Self {
            item: one.item,
            ndim: one.ndim + 1,
            shape,
            strides,
        }
    }

    /// A vector of `len` `float32`.
    pub(crate) fn vector(len: usize) -> Self {
        Self {
            item: Item::F32,
            ndim: 1,
            shape: [len as npy_intp, 0, 0, 0],
            strides: [4, 0, 0, 0],
        }
    }
}

/// A numpy array over the memory at `ptr`, shaped by `layout`, with `base` as its base
/// object: the array (and every array made from it) holds a reference to `base`, which
/// must keep the memory valid. Writable or read-only as `writable` says; a read-only one
/// cannot be made writable (numpy asks the base for a writable buffer first, which no
/// base here exports).
///
/// # Safety
/// The bytes `layout` describes from `ptr` stay valid as long as `base` lives; when
/// `writable`, nobody else writes or reads them concurrently while an array is alive.
pub(crate) unsafe fn array<'py>(
    base: Bound<'py, PyAny>,
    ptr: *mut u8,
    layout: &Layout,
    writable: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let py = base.py();
    // Importing numpy first turns a missing numpy into an ImportError here, instead of
    // the panic of the numpy crate's first look-up of its C API.
    numpy_imported(py)?;
    let descr = match layout.item {
        Item::U8 => u8::get_dtype(py),
        Item::F32 => f32::get_dtype(py),
    };
    let (mut shape, mut strides) = (layout.shape, layout.strides);
    // SAFETY: numpy's C API, imported above; `PyArray_NewFromDescr` steals the descriptor's
    // reference and copies `shape` and `strides`; the data pointer is valid as the caller
    // guarantees for as long as `base` lives, and `PyArray_SetBaseObject` makes the array
    // hold `base` (it steals that reference, also when it fails).
    unsafe {
        let array = PY_ARRAY_API.PyArray_NewFromDescr(
            py,
            npyffi::get_type_object(py, npyffi::NpyTypes::PyArray_Type),
            descr.into_dtype_ptr(),
            layout.ndim,
            shape.as_mut_ptr(),
            strides.as_mut_ptr(),
            ptr.cast::<c_void>(),
            if writable { NPY_ARRAY_WRITEABLE } else { 0 },
            std::ptr::null_mut(),
        );
        if array.is_null() {
            return Err(PyErr::fetch(py));
        }
        let array = Bound::from_owned_ptr(py, array);
        if PY_ARRAY_API.PyArray_SetBaseObject(
            py,
            array.as_ptr().cast::<npyffi::PyArrayObject>(),
            base.into_ptr(),
        ) < 0
        {
            return Err(PyErr::fetch(py));
        }
        Ok(array)
    }
}

/// Imports numpy once per process.
fn numpy_imported(py: Python<'_>) -> PyResult<()> {
    use pyo3::sync::PyOnceLock;
    static NUMPY: PyOnceLock<()> = PyOnceLock::new();
    NUMPY
        .get_or_try_init(py, || py.import("numpy").map(drop))
        .map(drop)
}
