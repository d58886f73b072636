//! Finding the line of an OBJ file that a load error is about. `tobj` reports what is
//! wrong but not where; this reads the file again with tobj's own rules for the lines
//! it rejects, under the options relume reads with ([`load_options`]), so that an error
//! can name the line (`line 12: position parse error`).

use std::str::FromStr;

/// How relume has tobj read a file (`mesh` loads with them, [`locate`] follows their
/// rules): polygons triangulated, points and lines dropped.
pub(crate) fn load_options() -> tobj::LoadOptions {
    // The update keeps this compiling when features of tobj enabled elsewhere add fields.
    #[allow(clippy::needless_update)]
    tobj::LoadOptions {
        single_index: false,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    }
}

/// What a line of an OBJ file is rejected for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Problem {
    /// As `tobj::LoadError`, for the errors that come from one line.
    Load(tobj::LoadError),
    /// A vertex position that parses but is not finite (relume's own check): the bits
    /// of the position found (x, y, z divided by w, as tobj stores them).
    NonFinitePosition([u32; 3]),
}

/// The first line (1-based) with `problem`, and its text; `None` where no line has it
/// (the error did not come from one line).
pub fn locate(text: &str, problem: Problem) -> Option<(usize, &str)> {
    let mut counts = Counts::default();
    // Faces of the current object: tobj checks their indices against the elements read
    // when the object ends.
    let mut pending: Vec<Face> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let number = i + 1;
        let mut words = line.split_whitespace();
        let rejected = match words.next() {
            Some("v") => {
                counts.positions += 1;
                // tobj keeps the colours of the lines with r g b after x y z.
                let values: Vec<&str> = words.clone().collect();
                if values.len() == 6 && floats(values[3..].iter().copied(), 3).is_some() {
                    counts.colors += 1;
                }
                vertex_problem(words)
            }
            Some("vt") => {
                counts.texcoords += 1;
                floats(words, 2)
                    .is_none()
                    .then_some(Problem::Load(tobj::LoadError::TexcoordParseError))
            }
            Some("vn") => {
                counts.normals += 1;
                floats(words, 3)
                    .is_none()
                    .then_some(Problem::Load(tobj::LoadError::NormalParseError))
            }
            Some("f") | Some("l") => match face(words, &counts) {
                Some(corners) => {
                    // tobj drops faces of one or two corners (points, lines) unchecked.
                    if corners.len() >= 3 {
                        pending.push((number, line, corners));
                    }
                    None
                }
                None => Some(Problem::Load(tobj::LoadError::FaceParseError)),
            },
            Some("usemtl") => line
                .split_once(' ')
                .is_none_or(|(_, name)| name.trim().is_empty())
                .then_some(Problem::Load(tobj::LoadError::MaterialParseError)),
            Some("o") | Some("g") => {
                if let Some(found) = out_of_bounds(&pending, &counts, problem) {
                    return Some(found);
                }
                pending.clear();
                None
            }
            _ => None,
        };
        if rejected == Some(problem) {
            return Some((number, line));
        }
    }
    out_of_bounds(&pending, &counts, problem)
}

/// An `f` or `l` line: its number, its text and its corners' indices ([`face`]).
type Face<'a> = (usize, &'a str, Vec<[Option<usize>; 3]>);

/// The first of an object's faces with an index out of bounds of the elements read by
/// its end, when `problem` is such an error.
fn out_of_bounds<'a>(
    faces: &[Face<'a>],
    counts: &Counts,
    problem: Problem,
) -> Option<(usize, &'a str)> {
    let (k, count) = match problem {
        Problem::Load(tobj::LoadError::FaceVertexOutOfBounds) => (0, counts.positions),
        // tobj ignores texture and normal indices where the file has none.
        Problem::Load(tobj::LoadError::FaceTexCoordOutOfBounds) if counts.texcoords > 0 => {
            (1, counts.texcoords)
        }
        Problem::Load(tobj::LoadError::FaceNormalOutOfBounds) if counts.normals > 0 => {
            (2, counts.normals)
        }
        // Once any vertex has a colour, every vertex a face uses needs one: a face's
        // position index is its colour index.
        Problem::Load(tobj::LoadError::FaceColorOutOfBounds) if counts.colors > 0 => {
            (0, counts.colors)
        }
        _ => return None,
    };
    faces
        .iter()
        .find(|(_, _, corners)| corners.iter().any(|c| c[k].is_some_and(|i| i >= count)))
        .map(|&(number, line, _)| (number, line))
}

/// Elements read so far.
#[derive(Default)]
struct Counts {
    positions: usize,
    texcoords: usize,
    normals: usize,
    /// `v` lines with a colour.
    colors: usize,
}

/// The first `n` words as floats, if there are `n` and they all parse.
fn floats<'a>(words: impl Iterator<Item = &'a str>, n: usize) -> Option<Vec<f32>> {
    let values: Vec<f32> = words
        .take(n)
        .map(f32::from_str)
        .collect::<Result<_, _>>()
        .ok()?;
    (values.len() == n).then_some(values)
}

/// What is wrong with a `v` line (its words after `v`): x y z, then nothing, a w that
/// scales them, or r g b.
fn vertex_problem<'a>(mut words: impl Iterator<Item = &'a str>) -> Option<Problem> {
    let Some(xyz) = floats(&mut words, 3) else {
        return Some(Problem::Load(tobj::LoadError::PositionParseError));
    };
    let rest: Vec<&str> = words.collect();
    // tobj divides by w where the line has one.
    let w = match rest[..] {
        [] | [_, _, _] => None,
        [w] => match f32::from_str(w) {
            Ok(0.0) => return Some(Problem::Load(tobj::LoadError::ScalingByZeroError)),
            Ok(w) => Some(w),
            Err(_) => return Some(Problem::Load(tobj::LoadError::PositionParseError)),
        },
        _ => return Some(Problem::Load(tobj::LoadError::ColorParseError)),
    };
    let position = match w {
        Some(w) => [xyz[0] / w, xyz[1] / w, xyz[2] / w],
        None => [xyz[0], xyz[1], xyz[2]],
    };
    (!position.iter().all(|c| c.is_finite()))
        .then(|| Problem::NonFinitePosition(position.map(f32::to_bits)))
}

/// The corners of an `f` (or `l`) line as 0-based (position, texcoord, normal) indices,
/// relative ones resolved against the elements read so far, as tobj reads them; `None`
/// where tobj cannot parse it. A position index that resolves below zero (or a 0) is
/// `usize::MAX`, out of bounds.
fn face<'a>(
    words: impl Iterator<Item = &'a str>,
    counts: &Counts,
) -> Option<Vec<[Option<usize>; 3]>> {
    let sizes = [counts.positions, counts.texcoords, counts.normals];
    words
        .map(|corner| {
            let mut indices = [None; 3];
            for (k, part) in corner.split('/').enumerate() {
                if part.is_empty() {
                    continue;
                }
                let x = isize::from_str(part).ok()?;
                let slot = indices.get_mut(k)?;
                let resolved = if x < 0 { sizes[k] as isize + x } else { x - 1 };
                // tobj takes -1 (a 0, or a relative index one before the first) for
                // "missing", which a texture or normal index may be.
                *slot = match usize::try_from(resolved) {
                    Ok(i) => Some(i),
                    Err(_) if resolved == -1 && k > 0 => None,
                    Err(_) => Some(usize::MAX),
                };
            }
            Some(indices)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use tobj::LoadError;

    fn non_finite(p: [f32; 3]) -> Problem {
        Problem::NonFinitePosition(p.map(f32::to_bits))
    }

    fn line_of(text: &str, problem: Problem) -> Option<usize> {
        locate(text, problem).map(|(n, _)| n)
    }

    #[test]
    fn each_problem_is_found_on_its_line() {
        let good = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvt 0 0\n";
        let cases = [
            ("v 0 zero 0\n", Problem::Load(LoadError::PositionParseError)),
            ("v 0 0\n", Problem::Load(LoadError::PositionParseError)),
            ("v 0 0 0 0\n", Problem::Load(LoadError::ScalingByZeroError)),
            ("v 0 0 0 1 1\n", Problem::Load(LoadError::ColorParseError)),
            ("vn 0 x 1\n", Problem::Load(LoadError::NormalParseError)),
            ("vt 0\n", Problem::Load(LoadError::TexcoordParseError)),
            ("usemtl\n", Problem::Load(LoadError::MaterialParseError)),
            ("f 1 2 x\n", Problem::Load(LoadError::FaceParseError)),
            ("f 1/1/1/1 2 3\n", Problem::Load(LoadError::FaceParseError)),
            ("f 1 2 7\n", Problem::Load(LoadError::FaceVertexOutOfBounds)),
            (
                "f -1 -2 -9\n",
                Problem::Load(LoadError::FaceVertexOutOfBounds),
            ),
            (
                "f 1//3 2//1 3//1\n",
                Problem::Load(LoadError::FaceNormalOutOfBounds),
            ),
            (
                "f 1/2 2/1 3/1\n",
                Problem::Load(LoadError::FaceTexCoordOutOfBounds),
            ),
            ("v 0 nan 0\n", non_finite([0.0, f32::NAN, 0.0])),
            ("v 1e30 0 0 1e-30\n", non_finite([f32::INFINITY, 0.0, 0.0])),
        ];
        for (bad, problem) in cases {
            let text = format!("{good}f 1 2 3\n{bad}f 1 2 3\n");
            assert_eq!(line_of(&text, problem), Some(7), "{bad:?}");
            // Not found where the file does not have it.
            assert_eq!(line_of(good, problem), None, "{bad:?}");
        }
    }

    #[test]
    fn indices_are_checked_against_the_elements_read_by_the_end_of_the_object() {
        // A face may refer to a vertex that comes after it in the same object.
        let later = "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n";
        let out_of_bounds = Problem::Load(LoadError::FaceVertexOutOfBounds);
        assert_eq!(line_of(later, out_of_bounds), None);
        // Not to one after the object ended.
        let next_object = "v 0 0 0\nv 1 0 0\nf 1 2 3\no second\nv 0 1 0\n";
        assert_eq!(line_of(next_object, out_of_bounds), Some(3));
    }

    /// The problem each case is located for is the one tobj reports for the file, read
    /// as relume reads it, and the line found is the one at fault.
    #[test]
    fn the_problems_are_the_ones_tobj_reports() {
        let options = load_options();
        for (text, problem, line) in [
            ("v 0 zero 0\n", LoadError::PositionParseError, 1),
            ("v 0 0 0 0\n", LoadError::ScalingByZeroError, 1),
            ("v 0 0 0 1 1\n", LoadError::ColorParseError, 1),
            ("vn 0 x 1\n", LoadError::NormalParseError, 1),
            ("vt 0\n", LoadError::TexcoordParseError, 1),
            ("usemtl \n", LoadError::MaterialParseError, 1),
            ("v 0 0 0\nf 1 x 1\n", LoadError::FaceParseError, 2),
            ("v 0 0 0\nf 1 1 7\n", LoadError::FaceVertexOutOfBounds, 2),
            // Points and lines are dropped unchecked: the face after them is at fault.
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 9\nf 1 9\nf 1 2 3\nf 1 2 9\n",
                LoadError::FaceVertexOutOfBounds,
                7,
            ),
            (
                "v 0 0 0\nvn 0 0 1\nf 1//1 1//2 1//1\n",
                LoadError::FaceNormalOutOfBounds,
                3,
            ),
            (
                "v 0 0 0\nvt 0 0\nf 1/1 1/2 1/1\n",
                LoadError::FaceTexCoordOutOfBounds,
                3,
            ),
            // Colours on some vertices only: the first face using one without is at
            // fault.
            (
                "v 0 0 0 1 1 1\nv 1 0 0\nv 0 1 0\nf 1 1 1\nf 1 2 3\n",
                LoadError::FaceColorOutOfBounds,
                5,
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1 1 1 1\nf 1 2 3\n",
                LoadError::FaceColorOutOfBounds,
                5,
            ),
        ] {
            let loaded = tobj::load_obj_buf(&mut text.as_bytes(), &options, |_| {
                Err(LoadError::OpenFileFailed)
            });
            assert_eq!(loaded.err(), Some(problem), "{text:?}");
            assert_eq!(
                line_of(text, Problem::Load(problem)),
                Some(line),
                "{text:?}"
            );
        }
    }
}
