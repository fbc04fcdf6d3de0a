//! Prints the face-edge adjacency table documented in `nebula_math::face`.

use nebula_math::{CubeFace, FaceEdge};

fn main() {
    for face in CubeFace::ALL {
        let row: Vec<String> = FaceEdge::ALL
            .iter()
            .map(|&edge| {
                let n = face.neighbor(edge);
                format!("{:?} {:?}{}", n.face, n.edge, if n.reversed { " (rev)" } else { "" })
            })
            .collect();
        println!("//! | {:?} | {} |", face, row.join(" | "));
    }
}
