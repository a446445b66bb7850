//! `.npy` input and output for motion, music and token arrays, with errors
//! that name the file and the expected shape.

use std::fs::File;
use std::io::{BufReader, BufWriter};
use std::path::Path;

use anyhow::{bail, Context, Result};
use npyz::{DType, NpyFile, TypeChar, WriterBuilder};

/// A row-major 2-D array read from an `.npy` file.
#[derive(Clone, Debug, PartialEq)]
pub struct Array2<T> {
    pub data: Vec<T>, // (rows, cols)
    pub rows: usize,
    pub cols: usize,
}

fn open(path: &Path) -> Result<NpyFile<BufReader<File>>> {
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    NpyFile::new(BufReader::new(file))
        .with_context(|| format!("{} is not a valid .npy file", path.display()))
}

fn shape_2d(path: &Path, shape: &[u64], cols: Option<usize>, what: &str) -> Result<(usize, usize)> {
    let (rows, c) = match shape {
        [r, c] => (*r as usize, *c as usize),
        // A 3-D (T, J, 3) array is accepted as (T, J*3).
        [r, j, k] => (*r as usize, (*j as usize).saturating_mul(*k as usize)),
        _ => bail!(
            "{}: expected a 2-D array of {what}, found shape {:?}",
            path.display(),
            shape
        ),
    };
    if let Some(want) = cols {
        if c != want {
            bail!(
                "{}: expected {what} with {want} columns per row, found shape {:?}",
                path.display(),
                shape
            );
        }
    }
    Ok((rows, c))
}

/// Reads a float array of shape (rows, cols) (float32 or float64; float64 is
/// rounded to f32). `cols`, when given, is checked. Fortran order is rejected.
pub fn read_f32_2d(path: &Path, cols: Option<usize>, what: &str) -> Result<Array2<f32>> {
    let npy = open(path)?;
    if npy.order() != npyz::Order::C {
        bail!(
            "{}: Fortran-ordered arrays are not supported; save with np.ascontiguousarray",
            path.display()
        );
    }
    let (rows, c) = shape_2d(path, npy.shape(), cols, what)?;
    let data: Vec<f32> = match npy.dtype() {
        DType::Plain(ts) if ts.type_char() == TypeChar::Float && ts.size_field() == 4 => npy
            .into_vec::<f32>()
            .with_context(|| format!("{}: truncated or unreadable float32 data", path.display()))?,
        DType::Plain(ts) if ts.type_char() == TypeChar::Float && ts.size_field() == 8 => npy
            .into_vec::<f64>()
            .with_context(|| format!("{}: truncated or unreadable float64 data", path.display()))?
            .into_iter()
            .map(|v| v as f32)
            .collect(),
        other => bail!(
            "{}: expected float32 {what}, found dtype {}",
            path.display(),
            other.descr()
        ),
    };
    if data.len() != rows * c {
        bail!(
            "{}: {} values do not fill shape ({rows}, {c})",
            path.display(),
            data.len()
        );
    }
    Ok(Array2 {
        data,
        rows,
        cols: c,
    })
}

/// Reads an integer array (any int/uint width) of shape (rows, cols) or (n,)
/// (read as (1, n)) as i64.
pub fn read_i64_2d(path: &Path, cols: Option<usize>, what: &str) -> Result<Array2<i64>> {
    let npy = open(path)?;
    let shape: Vec<u64> = match npy.shape() {
        [n] => vec![1, *n],
        s => s.to_vec(),
    };
    let (rows, c) = shape_2d(path, &shape, cols, what)?;
    let data: Vec<i64> = match npy.dtype() {
        DType::Plain(ts) if ts.type_char() == TypeChar::Int => match ts.size_field() {
            8 => npy.into_vec::<i64>()?,
            4 => npy.into_vec::<i32>()?.into_iter().map(i64::from).collect(),
            2 => npy.into_vec::<i16>()?.into_iter().map(i64::from).collect(),
            _ => npy.into_vec::<i8>()?.into_iter().map(i64::from).collect(),
        },
        DType::Plain(ts) if ts.type_char() == TypeChar::Uint => match ts.size_field() {
            4 => npy.into_vec::<u32>()?.into_iter().map(i64::from).collect(),
            2 => npy.into_vec::<u16>()?.into_iter().map(i64::from).collect(),
            1 => npy.into_vec::<u8>()?.into_iter().map(i64::from).collect(),
            _ => bail!(
                "{}: unsigned 64-bit {what} are not supported",
                path.display()
            ),
        },
        other => bail!(
            "{}: expected integer {what}, found dtype {}",
            path.display(),
            other.descr()
        ),
    };
    if data.len() != rows * c {
        bail!(
            "{}: {} values do not fill shape ({rows}, {c})",
            path.display(),
            data.len()
        );
    }
    Ok(Array2 {
        data,
        rows,
        cols: c,
    })
}

/// Writes a little-endian float32 array with the given shape.
pub fn write_f32(path: &Path, data: &[f32], shape: &[usize]) -> Result<()> {
    write_any(path, data, shape)
}

/// Writes a little-endian int64 array with the given shape.
pub fn write_i64(path: &Path, data: &[i64], shape: &[usize]) -> Result<()> {
    write_any(path, data, shape)
}

fn write_any<T: npyz::Serialize + npyz::AutoSerialize + Copy>(
    path: &Path,
    data: &[T],
    shape: &[usize],
) -> Result<()> {
    let n: usize = shape.iter().product();
    if n != data.len() {
        bail!(
            "internal: {} values do not fill shape {:?} for {}",
            data.len(),
            shape,
            path.display()
        );
    }
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let shape64: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&shape64)
        .writer(BufWriter::new(file))
        .begin_nd()
        .with_context(|| format!("cannot write {}", path.display()))?;
    w.extend(data.iter().copied())
        .with_context(|| format!("cannot write {}", path.display()))?;
    w.finish()
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_and_i64_round_trip_with_shape_checks() {
        let dir = std::env::temp_dir().join(format!("duo-npy-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.npy");
        let v: Vec<f32> = (0..12).map(|i| i as f32 * 0.5).collect();
        write_f32(&p, &v, &[4, 3]).unwrap();
        let a = read_f32_2d(&p, Some(3), "rows").unwrap();
        assert_eq!((a.rows, a.cols), (4, 3));
        assert_eq!(a.data, v);
        let err = read_f32_2d(&p, Some(165), "leader pos3d")
            .unwrap_err()
            .to_string();
        assert!(err.contains("165 columns"), "{err}");
        let q = dir.join("t.npy");
        write_i64(&q, &[1, 2, 3, 4, 5, 6], &[2, 3]).unwrap();
        let t = read_i64_2d(&q, Some(3), "tokens").unwrap();
        assert_eq!(t.data, vec![1, 2, 3, 4, 5, 6]);
        std::fs::write(dir.join("bad.npy"), b"not an npy").unwrap();
        assert!(read_f32_2d(&dir.join("bad.npy"), None, "x").is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
