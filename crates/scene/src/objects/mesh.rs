//! Triangle meshes from Wavefront OBJ files, read with `tobj`: polygons are triangulated
//! as fans, points and lines are ignored, relative (negative) indices are resolved, and
//! `mtllib`/`usemtl` are ignored (the material comes from the pipeline config). Normals
//! come from the file when every face corner has one (`f v//vn`); otherwise each vertex
//! gets the area-weighted mean of the normals of the faces around it, so that shading is
//! smooth across faces that share the vertex.

use super::error::ObjectError;
use super::geometry::{Triangle, tri_normal};
use super::obj_lines::{Problem, load_options, locate};
use glam::Vec3;
use std::path::Path;

/// Loads the OBJ file at `path` as triangles in its own coordinates (material 0).
/// Errors name the file, what is wrong (unreadable, not OBJ, bad indices, non-finite
/// positions, no triangles or none with an area) and, where one line is at fault, the
/// line.
pub fn load_obj(path: &Path) -> Result<Vec<Triangle>, ObjectError> {
    let bytes =
        relume_base::files::read_regular(path).map_err(|source| ObjectError::MeshUnreadable {
            path: path.to_path_buf(),
            source,
        })?;
    parse_obj(&bytes, path)
}

/// [`load_obj`] on the bytes of an OBJ file; `path` names it in errors.
pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<Vec<Triangle>, ObjectError> {
    // tobj reads lines of text: say where one is not.
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let line = bytes[..e.valid_up_to()]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1;
        ObjectError::MeshInvalid {
            path: path.to_path_buf(),
            reason: format!("line {line}: not UTF-8 text"),
        }
    })?;
    let invalid = |reason: String, problem: Option<Problem>| {
        // The line at fault, where one is (tobj does not say which).
        let line = problem.and_then(|problem| locate(text, problem));
        let reason = match line {
            Some((number, text)) => format!("line {number} (`{}`): {reason}", shorten(text)),
            None => reason,
        };
        ObjectError::MeshInvalid {
            path: path.to_path_buf(),
            reason,
        }
    };
    let (models, _materials) = tobj::load_obj_buf(&mut &bytes[..], &load_options(), |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| invalid(e.to_string(), Some(Problem::Load(e))))?;
    let mut triangles = Vec::new();
    for model in &models {
        append_model(&model.mesh, &mut triangles).map_err(|(reason, problem)| {
            let reason = if model.name.is_empty() || model.name == "unnamed_object" {
                reason
            } else {
                format!("{reason} (in object `{}`)", model.name)
            };
            invalid(reason, problem)
        })?;
    }
    if triangles.is_empty() {
        return Err(ObjectError::MeshEmpty {
            path: path.to_path_buf(),
        });
    }
    // Rays never hit a triangle without an area: such a mesh would be an invisible
    // object.
    if !triangles.iter().any(|t| has_area(&t.vertices)) {
        return Err(ObjectError::MeshDegenerate {
            path: path.to_path_buf(),
            count: triangles.len(),
        });
    }
    Ok(triangles)
}

/// False where the corners repeat or lie on a line, at any size: the edges are scaled
/// to unit length in f64 first, so that neither huge nor tiny coordinates over- or
/// underflow the test.
fn has_area(v: &[Vec3; 3]) -> bool {
    let [a, b, c] = v.map(|p| p.as_dvec3());
    let (e1, e2) = (b - a, c - a);
    let size = e1.abs().max(e2.abs()).max_element();
    size > 0.0 && (e1 / size).cross(e2 / size) != glam::DVec3::ZERO
}

/// A line of the file for an error message: trimmed, and cut after 60 characters.
fn shorten(line: &str) -> String {
    let line = line.trim();
    match line.char_indices().nth(60) {
        Some((end, _)) => format!("{}...", line[..end].trim_end()),
        None => line.to_string(),
    }
}

/// Appends the triangles of one `tobj` mesh; the error says what is wrong, and which
/// problem of a line it is where it is one.
fn append_model(
    mesh: &tobj::Mesh,
    out: &mut Vec<Triangle>,
) -> Result<(), (String, Option<Problem>)> {
    if !mesh.positions.len().is_multiple_of(3) || !mesh.indices.len().is_multiple_of(3) {
        return Err(("the faces do not triangulate".into(), None));
    }
    let positions: Vec<Vec3> = mesh
        .positions
        .chunks_exact(3)
        .map(|p| Vec3::new(p[0], p[1], p[2]))
        .collect();
    if let Some(p) = positions.iter().find(|p| !p.is_finite()) {
        return Err((
            format!("a vertex position is not finite: {p}"),
            Some(Problem::NonFinitePosition(p.to_array().map(f32::to_bits))),
        ));
    }
    // tobj checks the file's indices; these are of the mesh it made.
    let bad_index = |indices: &[u32], count: usize, what: &str| match indices
        .iter()
        .find(|&&i| i as usize >= count)
    {
        Some(&i) => Err((
            format!(
                "a face refers to {what} {}, but there are only {count}",
                i + 1
            ),
            None,
        )),
        None => Ok(()),
    };
    bad_index(&mesh.indices, positions.len(), "vertex")?;
    let file_normals = !mesh.normals.is_empty() && mesh.normal_indices.len() == mesh.indices.len();
    let normals: Vec<Vec3> = if file_normals {
        let normals: Vec<Vec3> = mesh
            .normals
            .chunks_exact(3)
            .map(|n| Vec3::new(n[0], n[1], n[2]).normalize_or_zero())
            .collect();
        bad_index(&mesh.normal_indices, normals.len(), "normal")?;
        mesh.normal_indices
            .iter()
            .map(|&i| normals[i as usize])
            .collect()
    } else {
        let smooth = smooth_normals(&positions, &mesh.indices);
        mesh.indices.iter().map(|&i| smooth[i as usize]).collect()
    };
    for (corners, normals) in mesh.indices.chunks_exact(3).zip(normals.chunks_exact(3)) {
        let vertices = [0, 1, 2].map(|k| positions[corners[k] as usize]);
        let face = tri_normal(&vertices);
        // A zero file normal falls back to the face's own.
        let normals = [0, 1, 2].map(|k| {
            if normals[k] == Vec3::ZERO {
                face
            } else {
                normals[k]
            }
        });
        out.push(Triangle {
            vertices,
            normals,
            material: 0,
        });
    }
    Ok(())
}

/// Per vertex, the unit mean of the adjacent faces' normals weighted by their areas
/// (the unnormalized cross product is twice the area times the normal); zero for a
/// vertex on degenerate faces only.
pub fn smooth_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut sum = vec![Vec3::ZERO; positions.len()];
    for f in indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| positions[f[k] as usize]);
        let weighted = (b - a).cross(c - a);
        for &i in f {
            sum[i as usize] += weighted;
        }
    }
    sum.iter().map(|n| n.normalize_or_zero()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Vec<Triangle>, ObjectError> {
        parse_obj(text.as_bytes(), Path::new("m.obj"))
    }

    const CUBE_QUADS: &str = "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n\
        f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";

    #[test]
    fn quads_triangulate_and_get_area_weighted_smooth_normals() {
        let tris = parse(CUBE_QUADS).unwrap();
        assert_eq!(tris.len(), 12);
        assert!((crate::objects::shapes::volume(&tris) - 8.0).abs() < 1e-9);
        // Each corner touches three faces of equal area: the normal is the diagonal.
        let corner = tris[0].vertices[0];
        assert_eq!(corner, Vec3::new(-1.0, -1.0, -1.0));
        let expected = Vec3::splat(-1.0).normalize();
        assert!(
            tris[0].normals[0].abs_diff_eq(expected, 1e-6),
            "{}",
            tris[0].normals[0]
        );
    }

    #[test]
    fn area_weights_favour_the_larger_face() {
        // Two triangles meeting at the origin: a big one in the xy plane (normal +z) and
        // a small one in the yz plane (normal +x), areas 2 and 0.125.
        let tris =
            parse("v 0 0 0\nv 2 0 0\nv 0 2 0\nv 0 0 -0.5\nv 0 0.5 0\nf 1 2 3\nf 1 4 5\n").unwrap();
        let n = tris[0].normals[0];
        let expected = (Vec3::Z * 4.0 + Vec3::X * 0.25).normalize();
        assert!(n.abs_diff_eq(expected, 1e-6), "{n} vs {expected}");
        // The unshared corners keep their own face's normal.
        assert_eq!(tris[0].normals[1], Vec3::Z);
        assert_eq!(tris[1].normals[1], Vec3::X);
    }

    #[test]
    fn file_normals_are_used_and_normalized() {
        let tris =
            parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 2\nvn 0 1 0\nf 1//1 2//2 3//1\n").unwrap();
        assert_eq!(tris[0].normals, [Vec3::Z, Vec3::Y, Vec3::Z]);
        // Negative (relative) indices resolve against the vertices read so far.
        let rel = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n").unwrap();
        assert_eq!(rel[0].vertices[2], Vec3::Y);
    }

    #[test]
    fn errors_name_the_file_and_the_problem() {
        let e = parse("v 0 0 0\nv 1 0 0\nf 1 2 7\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "the mesh `m.obj` is not a valid OBJ file: line 3 (`f 1 2 7`): face vertex index out of bounds"
        );
        let e = parse("# only points and lines\nv 0 0 0\nv 1 0 0\nl 1 2\np 1\n").unwrap_err();
        assert_eq!(e.to_string(), "the mesh `m.obj` has no triangles");
        let degenerate = [
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 1\nf 2 2 3\n",
            "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
            "v 0 0 0\nv 1e30 0 0\nv 2e30 0 0\nf 1 2 3\n",
        ];
        for (text, count) in degenerate.into_iter().zip([2, 1, 1]) {
            let e = parse(text).unwrap_err();
            assert_eq!(
                e.to_string(),
                format!(
                    "the mesh `m.obj` has no triangle with an area: all {count} have repeated or collinear corners"
                ),
                "{text}"
            );
        }
        // One triangle with an area is enough; the degenerate ones are kept, unhit.
        let tris = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 1\nf 1 2 3\n").unwrap();
        assert_eq!(tris.len(), 2);
        // Size alone does not make a triangle degenerate (whether it fits the world is
        // checked once it is placed).
        for text in [
            "v 0 0 0\nv 1e-30 0 0\nv 0 1e-30 0\nf 1 2 3\n",
            "v 1e30 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        ] {
            assert_eq!(parse(text).unwrap().len(), 1, "{text}");
        }
        let e = parse("v 0 nan 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "the mesh `m.obj` is not a valid OBJ file: line 1 (`v 0 nan 0`): a vertex position is not finite: [0, NaN, 0]"
        );
        let e = parse("# a cube\nv 0 0 0\n\nv 0 zero 0\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "the mesh `m.obj` is not a valid OBJ file: line 4 (`v 0 zero 0`): position parse error"
        );
        // A long line is cut.
        let long = format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3{}x\r\n", " 1".repeat(40));
        assert_eq!(
            parse(&long).unwrap_err().to_string(),
            format!(
                "the mesh `m.obj` is not a valid OBJ file: line 4 (`f 1 2 3{}...`): face parse error",
                " 1".repeat(26)
            )
        );
        // The line of the vertex found, not an earlier one that no face uses.
        let e = parse("v inf 0 0\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 nan 0\nf 2 3 5\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "the mesh `m.obj` is not a valid OBJ file: line 5 (`v 0 nan 0`): a vertex position is not finite: [0, NaN, 0]"
        );
        let e = parse_obj(b"v 0 0 0\n# caf\xe9\n", Path::new("m.obj")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the mesh `m.obj` is not a valid OBJ file: line 2: not UTF-8 text"
        );
        let e = load_obj(Path::new("/nonexistent/relume/m.obj")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "cannot read the mesh `/nonexistent/relume/m.obj`: No such file or directory (os error 2)"
        );
    }
}
