//! Reading float arrays from NumPy `.npy` files and `.npz` archives (through `npyz`), as `f64` in
//! C order, with errors that name the file and the array; writing them back as float64.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use npyz::{NpyFile, Order};

use crate::error::{Result, SceneError};

/// An n-dimensional float array in C (row-major) order.
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    pub shape: Vec<usize>,
    pub data: Vec<f64>,
}

/// Parses one `.npy` payload held in memory. `what` names the array in errors.
fn parse_npy(bytes: &[u8], what: &str, path: &Path) -> Result<Array> {
    let bad = |m: String| SceneError::format(path, format!("{what}: {m}"));
    let npy = NpyFile::new(bytes).map_err(|e| bad(format!("not a valid .npy array ({e})")))?;
    let header = npy.header().clone();
    let payload: &[u8] = npy.into_inner();
    let shape: Vec<usize> = header.shape().iter().map(|&s| s as usize).collect();
    let order = header.order();
    let count = header.len() as usize;
    // Refuse headers that promise more elements than the payload holds before allocating.
    let dtype = header.dtype().descr();
    let Some(item_bytes) = (match header.dtype() {
        npyz::DType::Plain(t) => t.num_bytes(),
        _ => None,
    }) else {
        return Err(bad(format!("dtype {dtype} is not a float32/float64 array")));
    };
    if count.saturating_mul(item_bytes) > payload.len() {
        return Err(bad(format!(
            "header says {count} elements of dtype {} but the payload is {} bytes",
            dtype,
            payload.len()
        )));
    }
    let npy = NpyFile::with_header(header, payload);
    let data: Vec<f64> = match npy.try_data::<f64>() {
        Ok(reader) => reader
            .collect::<std::io::Result<_>>()
            .map_err(|e| bad(format!("truncated data ({e})")))?,
        Err(npy) => match npy.try_data::<f32>() {
            Ok(reader) => reader
                .map(|r| r.map(f64::from))
                .collect::<std::io::Result<_>>()
                .map_err(|e| bad(format!("truncated data ({e})")))?,
            Err(_) => return Err(bad(format!("dtype {dtype} is not a float32/float64 array"))),
        },
    };
    let data = match order {
        Order::C => data,
        Order::Fortran => fortran_to_c(&data, &shape),
    };
    Ok(Array { shape, data })
}

/// Reorders a Fortran-order (first index fastest) buffer into C order.
fn fortran_to_c(data: &[f64], shape: &[usize]) -> Vec<f64> {
    let n = data.len();
    let mut out = vec![0.0; n];
    let mut index = vec![0usize; shape.len()];
    for slot in &mut out {
        // `index` walks C order; its Fortran offset is Σ index[k]·Π_{j<k} shape[j].
        let mut offset = 0;
        let mut stride = 1;
        for (k, &i) in index.iter().enumerate() {
            offset += i * stride;
            stride *= shape[k];
        }
        *slot = data[offset];
        for k in (0..shape.len()).rev() {
            index[k] += 1;
            if index[k] < shape[k] {
                break;
            }
            index[k] = 0;
        }
    }
    out
}

/// Reads a `.npy` file of floats.
pub fn read_npy(path: &Path) -> Result<Array> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    parse_npy(&bytes, "array", path)
}

/// Reads every float array of a `.npz` archive, by name (without the `.npy` suffix).
pub fn read_npz(path: &Path) -> Result<BTreeMap<String, Array>> {
    let mut archive = npyz::npz::NpzArchive::open(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound | std::io::ErrorKind::PermissionDenied => {
            SceneError::io(path, e)
        }
        _ => SceneError::format(path, format!("not a valid .npz archive ({e})")),
    })?;
    let names: Vec<String> = archive.array_names().map(str::to_owned).collect();
    let mut out = BTreeMap::new();
    for name in names {
        let file_name = npyz::npz::file_name_from_array_name(&name);
        let mut entry = archive
            .zip_archive()
            .by_name(&file_name)
            .map_err(|e| SceneError::format(path, format!("{name}: cannot open entry ({e})")))?;
        let mut bytes = Vec::new();
        entry
            .read_to_end(&mut bytes)
            .map_err(|e| SceneError::format(path, format!("{name}: corrupt entry ({e})")))?;
        let array = parse_npy(&bytes, &name, path)?;
        out.insert(name, array);
    }
    Ok(out)
}

/// Writes `array` as a float64 `.npy` file, atomically.
pub fn save_npy(path: &Path, array: &Array) -> Result<()> {
    use npyz::WriterBuilder;
    crate::atomic::write_with(path, |w| {
        let mut npy = npyz::WriteOptions::new()
            .default_dtype()
            .shape(&shape_u64(&array.shape))
            .writer(w)
            .begin_nd()?;
        npy.extend(array.data.iter().copied())?;
        npy.finish()
    })
}

/// Writes `arrays` as float64 entries of an uncompressed `.npz` (what NumPy's `np.savez`
/// writes), atomically.
pub fn save_npz(path: &Path, arrays: &BTreeMap<String, Array>) -> Result<()> {
    use npyz::WriterBuilder;
    crate::atomic::write_with(path, |w| {
        let mut npz = npyz::npz::NpzWriter::new(w);
        for (name, array) in arrays {
            let mut npy = npz
                .array::<f64>(name, Default::default())?
                .default_dtype()
                .shape(&shape_u64(&array.shape))
                .begin_nd()?;
            npy.extend(array.data.iter().copied())?;
            npy.finish()?;
        }
        Ok(())
    })
}

fn shape_u64(shape: &[usize]) -> Vec<u64> {
    shape.iter().map(|&s| s as u64).collect()
}

#[cfg(test)]
pub(crate) mod test_util {
    //! Writers for test fixtures (npyz's own writer, so the reader is checked against it).
    use std::path::Path;

    use npyz::WriterBuilder;

    pub fn write_npy(path: &Path, shape: &[u64], data: &[f64]) {
        let mut w = npyz::WriteOptions::new()
            .default_dtype()
            .shape(shape)
            .writer(std::fs::File::create(path).unwrap())
            .begin_nd()
            .unwrap();
        w.extend(data.iter().copied()).unwrap();
        w.finish().unwrap();
    }

    /// Writes float32 arrays into an `.npz`, as NumPy's `np.savez` does.
    pub fn write_npz(path: &Path, arrays: &[(&str, Vec<u64>, Vec<f64>)]) {
        let mut npz = npyz::npz::NpzWriter::create(path).unwrap();
        for (name, shape, data) in arrays {
            let mut w = npz
                .array::<f32>(name, Default::default())
                .unwrap()
                .default_dtype()
                .shape(shape)
                .begin_nd()
                .unwrap();
            w.extend(data.iter().map(|&v| v as f32)).unwrap();
            w.finish().unwrap();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::test_util::*;
    use super::*;

    #[test]
    fn npy_roundtrip_and_fortran_order() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.npy");
        let data: Vec<f64> = (0..6).map(|i| i as f64 * 0.5).collect();
        write_npy(&p, &[2, 3], &data);
        let a = read_npy(&p).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.data, data);
        // Fortran buffer of [[0,1,2],[3,4,5]] is 0,3,1,4,2,5.
        assert_eq!(
            fortran_to_c(&[0.0, 3.0, 1.0, 4.0, 2.0, 5.0], &[2, 3]),
            vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
        );
    }

    #[test]
    fn npz_float32_arrays_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.npz");
        write_npz(&p, &[("m_0", vec![2, 2], vec![1.0, 2.0, 3.0, 0.25])]);
        let m = read_npz(&p).unwrap();
        assert_eq!(m["m_0"].data, vec![1.0, 2.0, 3.0, 0.25]);
    }

    #[test]
    fn saved_arrays_read_back_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let a = Array {
            shape: vec![2, 3],
            data: vec![0.1, -2.5, 1e-300, 3.0, f64::MAX, 7.0],
        };
        let p = dir.path().join("a.npy");
        save_npy(&p, &a).unwrap();
        assert_eq!(read_npy(&p).unwrap(), a);
        let arrays: BTreeMap<String, Array> = [("x".to_owned(), a.clone()), ("y".to_owned(), a)]
            .into_iter()
            .collect();
        let z = dir.path().join("b.npz");
        save_npz(&z, &arrays).unwrap();
        assert_eq!(read_npz(&z).unwrap(), arrays);
    }

    #[test]
    fn corrupt_and_truncated_files_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.npy");
        std::fs::write(&p, b"\x93NUMPY garbage").unwrap();
        let e = read_npy(&p).unwrap_err().to_string();
        assert!(
            e.contains("bad.npy") && e.contains("not a valid .npy"),
            "{e}"
        );
        // A valid header whose payload is cut short.
        let q = dir.path().join("short.npy");
        write_npy(&q, &[4, 4], &[1.0; 16]);
        let bytes = std::fs::read(&q).unwrap();
        std::fs::write(&q, &bytes[..bytes.len() - 40]).unwrap();
        let e = read_npy(&q).unwrap_err().to_string();
        assert!(e.contains("short.npy") && e.contains("bytes"), "{e}");
        let z = dir.path().join("bad.npz");
        std::fs::write(&z, b"PK not really").unwrap();
        let e = read_npz(&z).unwrap_err().to_string();
        assert!(
            e.contains("bad.npz") && e.contains("not a valid .npz"),
            "{e}"
        );
    }
}
