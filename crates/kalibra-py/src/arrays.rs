//! numpy arrays in and out: any of the dtypes the NPZ reader takes (float64, float32, int64,
//! int32), in any memory layout, read as f64 values in C (row-major) order; results are new
//! float64 arrays.

use numpy::ndarray::{ArrayD, IxDyn};
use numpy::{
    Element, IntoPyArray, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use rayon::prelude::*;

use crate::error;

/// An array as read: its shape and its values in C order.
pub(crate) struct Array {
    pub shape: Vec<usize>,
    pub data: Vec<f64>,
}

impl Array {
    /// The number of leading axes before the last `trailing`.
    pub fn leading(&self, trailing: usize) -> &[usize] {
        &self.shape[..self.shape.len() - trailing]
    }
}

/// Values from which a contiguous array is copied on several threads (half a megabyte).
const PARALLEL_COPY_FROM: usize = 1 << 16;

/// The values of a numpy array of element type `T`, in C order whatever its strides.
fn values<T: Element + Copy + Sync>(
    obj: &Bound<'_, PyAny>,
    name: &str,
    convert: impl Fn(T) -> f64 + Sync + Send,
) -> PyResult<Option<Array>> {
    let Ok(array) = obj.cast::<PyArrayDyn<T>>() else {
        return Ok(None);
    };
    let view = array
        .try_readonly()
        .map_err(|e| error(format!("argument {name}: cannot read the array ({e})")))?;
    let a = view.as_array();
    // A C-contiguous array is one slice (a straight copy); any other layout is read in its
    // logical (C) order element by element.
    // (`as_slice` alone would also take a Fortran-ordered array, in its memory order.)
    //
    // A large contiguous array is copied on every core (rayon collects an indexed iterator
    // straight into the new vector): most of a large copy's cost is the kernel handing out and
    // zeroing the new pages, which several threads do side by side
    // (`crates/kalibra-py/bench/bench.py` shows it). The GIL is held, so no Python code changes
    // the array meanwhile.
    let data = match view.as_slice() {
        Ok(slice) if array.is_c_contiguous() && slice.len() >= PARALLEL_COPY_FROM => slice
            .par_iter()
            .with_min_len(PARALLEL_COPY_FROM / 4)
            .map(|&v| convert(v))
            .collect(),
        Ok(slice) if array.is_c_contiguous() => slice.iter().map(|&v| convert(v)).collect(),
        _ => a.iter().map(|&v| convert(v)).collect(),
    };
    Ok(Some(Array {
        shape: a.shape().to_vec(),
        data,
    }))
}

/// Reads argument `name`: a numpy array of float64, float32, int64 or int32 (any layout), or
/// anything `numpy.asarray` turns into one (nested lists).
pub(crate) fn read(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Array> {
    let as_array;
    let obj = if obj.is_instance_of::<PyUntypedArray>() {
        // numpy arrays need not be aligned (pickle's out-of-band buffers, as Dask ships them;
        // `frombuffer` at an odd offset), and rust-numpy reads only aligned ones: an unaligned
        // array is copied by numpy into an aligned one first.
        if obj
            .getattr("flags")?
            .getattr("aligned")?
            .extract::<bool>()?
        {
            obj
        } else {
            let numpy = obj.py().import("numpy")?;
            as_array = numpy.call_method1("require", (obj, obj.py().None(), "A"))?;
            &as_array
        }
    } else {
        let numpy = obj.py().import("numpy")?;
        as_array = numpy.call_method1("asarray", (obj,)).map_err(|e| {
            error(format!(
                "argument {name}: not an array and not convertible to one ({e})"
            ))
        })?;
        &as_array
    };
    if let Some(a) = values::<f64>(obj, name, |v| v)? {
        return Ok(a);
    }
    if let Some(a) = values::<f32>(obj, name, f64::from)? {
        return Ok(a);
    }
    #[allow(clippy::cast_precision_loss)]
    if let Some(a) = values::<i64>(obj, name, |v| v as f64)? {
        return Ok(a);
    }
    if let Some(a) = values::<i32>(obj, name, f64::from)? {
        return Ok(a);
    }
    let dtype = obj
        .cast::<PyUntypedArray>()
        .map(|a| a.dtype().to_string())
        .unwrap_or_else(|_| "unknown".into());
    Err(error(format!(
        "argument {name}: dtype {dtype} is not a number type kalibra reads (float64, float32, \
         int64, int32)"
    )))
}

/// An argument's values for a call that reads them without the GIL: numpy's own memory when
/// it can be read as it is, else a copy.
pub(crate) enum InPlace<'py> {
    /// A C-contiguous, aligned float64 numpy array, borrowed (rust-numpy's shared borrow, so
    /// no Rust code writes to it meanwhile) and set non-writeable while the guard lives.
    Numpy {
        view: PyReadonlyArrayDyn<'py, f64>,
        /// The array whose `writeable` flag this guard cleared, to set again on drop.
        frozen: Option<Bound<'py, PyAny>>,
    },
    /// Any other argument, converted as [`read`] does.
    Copied(Array),
}

impl InPlace<'_> {
    /// The shape.
    pub fn shape(&self) -> Vec<usize> {
        match self {
            InPlace::Numpy { view, .. } => view.shape().to_vec(),
            InPlace::Copied(a) => a.shape.clone(),
        }
    }

    /// The values in C order.
    pub fn data(&self) -> &[f64] {
        match self {
            // `read_in_place` made this variant only for an array `as_slice` accepted.
            InPlace::Numpy { view, .. } => view.as_slice().unwrap_or_default(),
            InPlace::Copied(a) => &a.data,
        }
    }
}

impl Drop for InPlace<'_> {
    fn drop(&mut self) {
        if let InPlace::Numpy {
            frozen: Some(array),
            ..
        } = self
        {
            // Setting back a flag that was set before succeeds; nothing to report from a drop
            // if numpy refused.
            let _ = array
                .getattr("flags")
                .and_then(|flags| flags.setattr("writeable", true));
        }
    }
}

/// Reads argument `name` for a call that releases the GIL: a C-contiguous, aligned float64
/// numpy array is read in place, not copied (a large log's copy is mostly the kernel handing
/// out fresh pages; `crates/kalibra-py/bench/bench.py` shows the cost), and is set
/// non-writeable until the returned guard drops, so that Python code writing to it through
/// this array object meanwhile gets numpy's read-only error instead of racing with the read.
/// (Other views of the same memory stay writeable: as for numpy's own functions that release
/// the GIL, the caller must not change the array from another thread during the call.)
/// Anything else is read by [`read`], into a copy.
pub(crate) fn read_in_place<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<InPlace<'py>> {
    if let Ok(array) = obj.cast::<PyArrayDyn<f64>>()
        && array.is_c_contiguous()
        && obj
            .getattr("flags")?
            .getattr("aligned")?
            .extract::<bool>()?
    {
        let view = array
            .try_readonly()
            .map_err(|e| error(format!("argument {name}: cannot read the array ({e})")))?;
        if view.as_slice().is_ok() {
            let flags = obj.getattr("flags")?;
            let frozen = if flags.getattr("writeable")?.extract::<bool>()? {
                flags.setattr("writeable", false)?;
                Some(obj.clone())
            } else {
                None
            };
            return Ok(InPlace::Numpy { view, frozen });
        }
    }
    read(obj, name).map(InPlace::Copied)
}

/// Reads an optional argument.
pub(crate) fn read_opt(obj: Option<&Bound<'_, PyAny>>, name: &str) -> PyResult<Option<Array>> {
    obj.filter(|o| !o.is_none())
        .map(|o| read(o, name))
        .transpose()
}

/// A new float64 array of `shape` holding `data` (C order).
// Every caller builds `data` from `shape` inside this crate: a mismatch is a bug here, never
// bad input from Python.
#[allow(clippy::expect_used)]
pub(crate) fn new_array<'py>(
    py: Python<'py>,
    shape: &[usize],
    data: Vec<f64>,
) -> Bound<'py, PyArrayDyn<f64>> {
    ArrayD::from_shape_vec(IxDyn(shape), data)
        .expect("the shape holds exactly the values")
        .into_pyarray(py)
}
