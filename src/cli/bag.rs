//! `garment_sim bag`: info, export and repair of rosbag2 (MCAP) bags.

use anyhow::Result;
use clap::Subcommand;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum BagCmd {
    /// Topics, message counts, duration, and whether the file is complete.
    Info {
        /// Bag directory (or its .mcap file).
        bag: PathBuf,
    },
    /// Write the cloth shape of one frame as PLY or OBJ, or a picture of it (PNG).
    Export {
        /// Bag directory (or its .mcap file).
        bag: PathBuf,
        /// Simulated time, s: the last frame at or before it.
        #[arg(long, conflicts_with = "last", required_unless_present = "last",
              allow_negative_numbers = true, value_parser = crate::cli::lab::seconds)]
        time: Option<f64>,
        /// The last frame.
        #[arg(long)]
        last: bool,
        /// ply, obj or png (the cloth and the obstacles drawn from three views).
        #[arg(long, default_value = "ply")]
        format: garment_sim::bag::ShapeFormat,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
        /// Point cloud topic.
        #[arg(long, default_value = "/cloth/points")]
        points_topic: String,
        /// Mesh marker topic (triangles).
        #[arg(long, default_value = "/cloth/mesh")]
        mesh_topic: String,
    },
    /// Rebuild summary, indexes and metadata.yaml of a bag cut short by a crash.
    Repair {
        /// Bag directory (or its .mcap file).
        bag: PathBuf,
    },
}

pub fn bag_cmd(cmd: BagCmd) -> Result<()> {
    use garment_sim::bag;
    match cmd {
        BagCmd::Info { bag: dir } => print!("{}", bag::info(&dir)?),
        BagCmd::Export {
            bag: dir,
            time,
            last,
            format,
            out,
            points_topic,
            mesh_topic,
        } => {
            let when = match (time, last) {
                (Some(t), false) => bag::ExportTime::At(t),
                _ => bag::ExportTime::Last,
            };
            let shape = bag::shape_at(&dir, when, &points_topic, &mesh_topic)?;
            bag::write_shape(&shape, format, &out)?;
            println!(
                "wrote {} (t = {:.6} s, {} vertices, {} triangles)",
                out.display(),
                shape.time_s,
                shape.vertices.len(),
                shape.faces.len()
            );
        }
        BagCmd::Repair { bag: dir } => {
            let r = bag::repair(&dir)?;
            if r.was_complete {
                println!(
                    "{}: complete; metadata.yaml rewritten",
                    r.bag.file.display()
                );
            } else {
                if let bag::Ending::Truncated { offset, reason } = &r.ending {
                    println!("{}: cut at byte {offset} ({reason})", r.bag.file.display());
                }
                for (offset, why) in &r.dropped_chunks {
                    println!("dropped the chunk at byte {offset}: {why}");
                }
                println!(
                    "repaired: {} messages in {} chunks kept, {} bytes of an incomplete chunk dropped; summary, indexes and metadata.yaml rebuilt",
                    r.bag.message_count, r.bag.chunks, r.bytes_dropped
                );
                if let Some(b) = &r.backup {
                    println!("the damaged file is kept as {}", b.display());
                }
            }
        }
    }
    Ok(())
}
