//! Float `.npy` arrays read one leading-axis row at a time (a frame of a `(T, J, C)` joint array),
//! by seeking, so that a dataset reads exactly the frames it hands out (see [`crate::readlog`]).

use std::fs::File;
use std::path::Path;

use npyz::{NpyFile, Order};

use crate::error::{HumanError, Result};

/// The shape of a C-order float32/float64 `.npy` array, read from its header only.
pub fn shape(path: &Path) -> Result<Vec<usize>> {
    let npy = open(path)?;
    Ok(npy.shape().iter().map(|&s| s as usize).collect())
}

/// Rows `row` of the array's leading axis, as `f64` in C order (`Π shape[1..]` values).
pub fn read_row(path: &Path, row: usize) -> Result<Vec<f64>> {
    let npy = open(path)?;
    let shape: Vec<usize> = npy.shape().iter().map(|&s| s as usize).collect();
    let rows = shape.first().copied().unwrap_or(1);
    if row >= rows {
        return Err(HumanError::invalid(
            path,
            format!("row {row} requested but the array has {rows} rows (shape {shape:?})"),
        ));
    }
    let row_len: usize = shape.iter().skip(1).product();
    let start = (row * row_len) as u64;
    let truncated = |e: std::io::Error| HumanError::format(path, format!("truncated data ({e})"));
    match npy.try_data::<f32>() {
        Ok(mut reader) => {
            reader.seek_to(start).map_err(truncated)?;
            take(&mut reader, row_len, path).map(|v| v.into_iter().map(f64::from).collect())
        }
        Err(npy) => {
            let mut reader = npy
                .try_data::<f64>()
                .map_err(|_| HumanError::format(path, "not a float32/float64 array"))?;
            reader.seek_to(start).map_err(truncated)?;
            take(&mut reader, row_len, path)
        }
    }
}

fn take<T>(
    reader: &mut impl Iterator<Item = std::io::Result<T>>,
    n: usize,
    path: &Path,
) -> Result<Vec<T>> {
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        match reader.next() {
            Some(Ok(v)) => out.push(v),
            Some(Err(e)) => return Err(HumanError::format(path, format!("truncated data ({e})"))),
            None => return Err(HumanError::format(path, "truncated data")),
        }
    }
    Ok(out)
}

/// Opens a `.npy` file and checks that it is a C-order float array whose payload is as long as
/// its header says.
fn open(path: &Path) -> Result<NpyFile<File>> {
    let file = File::open(path).map_err(|e| HumanError::io(path, e))?;
    let size = file.metadata().map_err(|e| HumanError::io(path, e))?.len();
    let npy = NpyFile::new(file)
        .map_err(|e| HumanError::format(path, format!("not a valid .npy array ({e})")))?;
    let descr = npy.dtype().descr();
    let item = match npy.dtype() {
        npyz::DType::Plain(t) if matches!(t.type_char(), npyz::TypeChar::Float) => t.num_bytes(),
        _ => None,
    };
    let Some(item) = item.filter(|&b| b == 4 || b == 8) else {
        return Err(HumanError::format(
            path,
            format!("dtype {descr} is not float32/float64"),
        ));
    };
    if npy.order() != Order::C {
        return Err(HumanError::format(
            path,
            "Fortran-order arrays are not supported",
        ));
    }
    if npy.len().saturating_mul(item as u64) > size {
        return Err(HumanError::format(
            path,
            format!(
                "header says {} values but the file is {size} bytes",
                npy.len()
            ),
        ));
    }
    Ok(npy)
}
