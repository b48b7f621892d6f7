//! The group's output arrays: numpy arrays it owns and writes into.

use pyo3::buffer::PyUntypedBuffer;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyTuple;

/// A writable, C-contiguous numpy array owned by the group, with its buffer export held
/// (numpy cannot resize or free it while exported).
pub(super) struct Out {
    pub(super) array: Py<PyAny>,
    pub(super) _export: PyUntypedBuffer,
    pub(super) ptr: usize,
}

impl Out {
    /// A new array of zeros.
    pub(super) fn new(
        py: Python<'_>,
        numpy: &Bound<'_, PyModule>,
        shape: &[usize],
        dtype: &str,
    ) -> PyResult<Self> {
        Self::make(py, numpy, "zeros", shape, dtype)
    }

    /// A new array whose contents are undefined until written.
    pub(super) fn empty(
        py: Python<'_>,
        numpy: &Bound<'_, PyModule>,
        shape: &[usize],
        dtype: &str,
    ) -> PyResult<Self> {
        Self::make(py, numpy, "empty", shape, dtype)
    }

    fn make(
        py: Python<'_>,
        numpy: &Bound<'_, PyModule>,
        function: &str,
        shape: &[usize],
        dtype: &str,
    ) -> PyResult<Self> {
        let array = numpy.call_method1(function, (PyTuple::new(py, shape)?, dtype))?;
        let export = PyUntypedBuffer::get(&array)?;
        if export.readonly() || !export.is_c_contiguous() {
            return Err(PyValueError::new_err(
                "numpy returned a read-only or non-contiguous array",
            ));
        }
        let ptr = export.buf_ptr() as usize;
        Ok(Self {
            array: array.unbind(),
            _export: export,
            ptr,
        })
    }
}
