//! What the `obstacles` and `pins` messages do to a running simulation.
//! Every message is checked in full before anything changes: a bad one is
//! refused with an error naming the field and index, and the scene is left
//! as it was.

use crate::collision::{Obstacle, ShapeSpec, DEFAULT_FRICTION, DEFAULT_OBSTACLE_THICKNESS};
use crate::garment::Garment;
use crate::limits::{self, MAX_ANGULAR_SPEED, MAX_OBSTACLE_SPEED, MAX_PIN_SPEED};
use crate::msgs;
use crate::set::{Handle, Set};
use crate::solver::{Pin, PinPath, Simulation};
use nalgebra::{Isometry3, Vector3};
use std::collections::HashMap;

/// Which simulation obstacles make up each message obstacle: an obstacle with
/// several primitives and meshes becomes several shapes (`id#0`, `id#1`, ...)
/// moved together, each with its pose relative to the obstacle frame.
#[derive(Debug, Default, Clone)]
pub struct ObstacleRegistry {
    parts: HashMap<String, Vec<Part>>,
}

/// One shape of a message obstacle: its simulation obstacle and its pose in
/// the obstacle frame.
type Part = (Handle<Obstacle>, Isometry3<f64>);

impl ObstacleRegistry {
    /// Registers the scene's own obstacles (one shape each).
    pub fn from_sim(sim: &Simulation) -> ObstacleRegistry {
        let mut r = ObstacleRegistry::default();
        for (h, o) in sim.obstacles().with_handles() {
            r.parts
                .insert(o.id.clone(), vec![(h, Isometry3::identity())]);
        }
        r
    }

    pub fn len(&self) -> usize {
        self.parts.len()
    }

    /// Removes the obstacle `id` (all its shapes) from the simulation and the
    /// registry; says whether there was one.
    pub fn remove_from(&mut self, sim: &mut Simulation, id: &str) -> bool {
        match self.parts.remove(id) {
            Some(parts) => {
                for (h, _) in parts {
                    sim.remove_obstacle(h);
                }
                true
            }
            None => false,
        }
    }

    pub fn contains(&self, id: &str) -> bool {
        self.parts.contains_key(id)
    }

    /// Registers the obstacle `id` as the one shape `h`.
    pub fn insert_single(&mut self, id: &str, h: Handle<Obstacle>) {
        self.parts
            .insert(id.to_string(), vec![(h, Isometry3::identity())]);
    }

    pub fn is_empty(&self) -> bool {
        self.parts.is_empty()
    }
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn check_frame(got: &str, frame_id: &str) -> Result<(), String> {
    if !got.is_empty() && got != frame_id {
        return Err(format!(
            "header.frame_id {got:?} is not the simulation frame {frame_id:?} \
             (the node does not use TF: send poses in {frame_id:?})"
        ));
    }
    Ok(())
}

fn pose(p: &msgs::Pose, what: &str) -> Result<Isometry3<f64>, String> {
    p.to_isometry().map_err(|e| format!("{what}: {e}"))
}

fn shape(p: &msgs::SolidPrimitive, k: usize) -> Result<ShapeSpec, String> {
    let d = &p.dimensions;
    let need = |n: usize, names: &str| -> Result<(), String> {
        if d.len() != n {
            return Err(format!(
                "primitives[{k}]: {} dimensions given, {n} expected ({names})",
                d.len()
            ));
        }
        if !finite(d) || d.iter().any(|x| *x <= 0.0) {
            return Err(format!("primitives[{k}]: dimensions {d:?} must be > 0 m"));
        }
        for (j, x) in d.iter().enumerate() {
            limits::check_size(&format!("primitives[{k}].dimensions[{j}]"), *x)
                .map_err(|e| e.to_string())?;
        }
        Ok(())
    };
    Ok(match p.type_ {
        msgs::SolidPrimitive::BOX => {
            need(3, "x, y, z")?;
            ShapeSpec::Box {
                size: [d[0], d[1], d[2]],
            }
        }
        msgs::SolidPrimitive::SPHERE => {
            need(1, "radius")?;
            ShapeSpec::Sphere { radius: d[0] }
        }
        msgs::SolidPrimitive::CYLINDER => {
            need(2, "height, radius")?;
            ShapeSpec::Cylinder {
                height: d[0],
                radius: d[1],
            }
        }
        msgs::SolidPrimitive::CONE => {
            need(2, "height, radius")?;
            ShapeSpec::Cone {
                height: d[0],
                radius: d[1],
            }
        }
        t => {
            return Err(format!(
                "primitives[{k}]: type {t} not supported (BOX=1, SPHERE=2, CYLINDER=3, CONE=4)"
            ))
        }
    })
}

/// The message's velocity (linear, angular), finite and within the speed
/// limits.
fn obstacle_twist(m: &msgs::Obstacle) -> Result<(Vector3<f64>, Vector3<f64>), String> {
    let id = m.id.as_str();
    let fail = |e: String| format!("obstacle {id:?}: {e}");
    let twist = [
        m.velocity.linear.x,
        m.velocity.linear.y,
        m.velocity.linear.z,
        m.velocity.angular.x,
        m.velocity.angular.y,
        m.velocity.angular.z,
    ];
    if !finite(&twist) {
        return Err(fail(format!("velocity {twist:?} is not finite")));
    }
    let lin = m.velocity.linear.vector();
    let ang = m.velocity.angular.vector();
    limits::check_speed("velocity.linear", &lin, MAX_OBSTACLE_SPEED, "m/s")
        .and_then(|_| limits::check_speed("velocity.angular", &ang, MAX_ANGULAR_SPEED, "rad/s"))
        .map_err(|e| fail(e.to_string()))?;
    Ok((lin, ang))
}

/// MOVE: every part of the obstacle moved to `frame` with the velocity
/// (`lin`, `ang`), each checked where it would go before any moves.
fn move_obstacle(
    sim: &mut Simulation,
    reg: &ObstacleRegistry,
    id: &str,
    frame: &Isometry3<f64>,
    (lin, ang): (Vector3<f64>, Vector3<f64>),
) -> Result<String, String> {
    let fail = |e: String| format!("obstacle {id:?}: {e}");
    let parts = reg
        .parts
        .get(id)
        .ok_or_else(|| fail("no such obstacle to move (ADD it first)".into()))?;
    // every part checked where it would go before any moves
    let mut moved = Vec::new();
    for &(h, sub) in parts {
        if let Some(o) = sim.obstacles().get(h) {
            let mut o = o.clone();
            set_motion(&mut o, frame, &sub, &lin, &ang);
            o.check_overlap(sim.cloth.positions())
                .map_err(|e| fail(e.to_string()))?;
            moved.push((h, o));
        }
    }
    for (h, o) in moved {
        if let Some(slot) = sim.obstacle_mut(h) {
            *slot = o;
        }
    }
    Ok(format!("moved obstacle {id:?}"))
}

/// The shapes of an ADD message (its primitives, then its meshes, at most
/// `max_triangles` each) with their poses in the obstacle frame.
fn obstacle_shapes(
    m: &msgs::Obstacle,
    max_triangles: usize,
) -> Result<Vec<(ShapeSpec, Isometry3<f64>)>, String> {
    let id = m.id.as_str();
    let fail = |e: String| format!("obstacle {id:?}: {e}");
    if m.primitives.len() != m.primitive_poses.len() {
        return Err(fail(format!(
            "{} primitives but {} primitive_poses",
            m.primitives.len(),
            m.primitive_poses.len()
        )));
    }
    if m.meshes.len() != m.mesh_poses.len() {
        return Err(fail(format!(
            "{} meshes but {} mesh_poses",
            m.meshes.len(),
            m.mesh_poses.len()
        )));
    }
    let mut specs = Vec::new();
    for (k, (p, q)) in m.primitives.iter().zip(&m.primitive_poses).enumerate() {
        specs.push((
            shape(p, k).map_err(fail)?,
            pose(q, &format!("primitive_poses[{k}]")).map_err(fail)?,
        ));
    }
    for (k, (mesh, q)) in m.meshes.iter().zip(&m.mesh_poses).enumerate() {
        if mesh.triangles.len() > max_triangles {
            return Err(fail(format!(
                "meshes[{k}] has {} triangles, more than max_mesh_triangles = {max_triangles}",
                mesh.triangles.len()
            )));
        }
        let vertices: Vec<[f64; 3]> = mesh.vertices.iter().map(|p| [p.x, p.y, p.z]).collect();
        let triangles = mesh.triangles.iter().map(|t| t.vertex_indices).collect();
        specs.push((
            ShapeSpec::Triangles {
                vertices,
                triangles,
            },
            pose(q, &format!("mesh_poses[{k}]")).map_err(fail)?,
        ));
    }
    if specs.is_empty() {
        return Err(fail("no primitives and no meshes".into()));
    }
    Ok(specs)
}

/// ADD: the obstacle's shapes built at `frame` with the velocity (`lin`,
/// `ang`), each checked against the cloth, then put in place of an obstacle
/// of the same id.
fn add_obstacle(
    sim: &mut Simulation,
    reg: &mut ObstacleRegistry,
    m: &msgs::Obstacle,
    frame: Isometry3<f64>,
    (lin, ang): (Vector3<f64>, Vector3<f64>),
    max_triangles: usize,
) -> Result<String, String> {
    let id = m.id.as_str();
    let fail = |e: String| format!("obstacle {id:?}: {e}");
    let thickness = if m.thickness.is_nan() {
        DEFAULT_OBSTACLE_THICKNESS
    } else {
        m.thickness
    };
    let friction = if m.friction.is_nan() {
        DEFAULT_FRICTION
    } else {
        m.friction
    };
    let specs = obstacle_shapes(m, max_triangles)?;
    let many = specs.len() > 1;
    let mut built = Vec::new();
    for (k, (spec, sub)) in specs.into_iter().enumerate() {
        let pid = if many {
            format!("{id}#{k}")
        } else {
            id.to_string()
        };
        let mut o = Obstacle::new(&pid, spec, frame * sub, thickness, friction)
            .map_err(|e| format!("{e:#}"))?;
        set_motion(&mut o, &frame, &sub, &lin, &ang);
        o.check_overlap(sim.cloth.positions())
            .map_err(|e| fail(e.to_string()))?;
        built.push((o, sub));
    }
    let replaced = if let Some(old) = reg.parts.remove(id) {
        for (h, _) in old {
            sim.remove_obstacle(h);
        }
        true
    } else {
        false
    };
    let n = built.len();
    let parts = built
        .into_iter()
        .map(|(o, sub)| (sim.add_obstacle(o), sub))
        .collect();
    reg.parts.insert(id.to_string(), parts);
    Ok(format!(
        "{} obstacle {id:?} ({n} shape{})",
        if replaced { "replaced" } else { "added" },
        if n == 1 { "" } else { "s" }
    ))
}

/// Applies an `obstacles` message. Returns a one-line account of what changed.
/// `max_triangles` bounds each mesh (parameter `max_mesh_triangles`).
pub fn apply_obstacle(
    sim: &mut Simulation,
    reg: &mut ObstacleRegistry,
    m: &msgs::Obstacle,
    frame_id: &str,
    max_triangles: usize,
) -> Result<String, String> {
    let id = m.id.as_str();
    let fail = |e: String| format!("obstacle {id:?}: {e}");
    if id.is_empty() {
        return Err("obstacle: empty id".into());
    }
    check_frame(&m.header.frame_id, frame_id).map_err(fail)?;
    let twist = obstacle_twist(m)?;
    let reach = |frame: &Isometry3<f64>, x: &[Vector3<f64>]| -> Result<(), String> {
        limits::check_reach("pose.position", &frame.translation.vector, x)
            .map_err(|e| fail(e.to_string()))
    };
    match m.operation {
        msgs::Obstacle::REMOVE => {
            let parts = reg
                .parts
                .remove(id)
                .ok_or_else(|| fail("no such obstacle to remove".into()))?;
            for (h, _) in parts {
                sim.remove_obstacle(h);
            }
            Ok(format!("removed obstacle {id:?}"))
        }
        msgs::Obstacle::MOVE => {
            let frame = pose(&m.pose, "pose").map_err(fail)?;
            reach(&frame, sim.cloth.positions())?;
            move_obstacle(sim, reg, id, &frame, twist)
        }
        msgs::Obstacle::ADD => {
            let frame = pose(&m.pose, "pose").map_err(fail)?;
            reach(&frame, sim.cloth.positions())?;
            add_obstacle(sim, reg, m, frame, twist, max_triangles)
        }
        op => Err(fail(format!(
            "operation {op} unknown (ADD=0, REMOVE=1, MOVE=3)"
        ))),
    }
}

fn set_motion(
    o: &mut Obstacle,
    frame: &Isometry3<f64>,
    sub: &Isometry3<f64>,
    lin: &Vector3<f64>,
    ang: &Vector3<f64>,
) {
    o.pose = frame * sub;
    let r = o.pose.translation.vector - frame.translation.vector;
    o.linear_velocity = lin + ang.cross(&r);
    o.angular_velocity = *ang;
}

/// Applies a `pins` message. Returns a one-line account of what changed.
/// `garment` is the scene's garment (a trial), whose panels `m.panel` names.
pub fn apply_pin(
    sim: &mut Simulation,
    garment: Option<&Garment>,
    m: &msgs::Pin,
    frame_id: &str,
) -> Result<String, String> {
    let fail = |e: String| format!("pins: {e}");
    check_frame(&m.header.frame_id, frame_id).map_err(fail)?;
    if m.operation == msgs::Pin::RELEASE_ALL {
        let n = sim.pins().len();
        sim.set_pins(Vec::new()).map_err(|e| fail(e.to_string()))?;
        return Ok(format!("released all {n} pins"));
    }
    let n = sim.cloth.len();
    let vertices: Vec<usize> = if !m.vertices.is_empty() {
        if !m.grid_i.is_empty() || !m.grid_j.is_empty() {
            return Err(fail("give vertices or grid_i/grid_j, not both".into()));
        }
        let mut v = Vec::with_capacity(m.vertices.len());
        for (k, &i) in m.vertices.iter().enumerate() {
            if i as usize >= n {
                return Err(fail(format!(
                    "vertices[{k}] = {i} out of range: the cloth has {n} vertices"
                )));
            }
            v.push(i as usize);
        }
        v
    } else {
        if m.grid_i.len() != m.grid_j.len() {
            return Err(fail(format!(
                "{} grid_i but {} grid_j",
                m.grid_i.len(),
                m.grid_j.len()
            )));
        }
        // a garment's grid nodes are its panels'; a sheet has one grid
        let panel = match (garment, m.panel.as_str()) {
            (None, "") => None,
            (None, name) => {
                return Err(fail(format!(
                    "panel {name:?} given, but the scene is a single sheet, not a garment (leave panel empty)"
                )))
            }
            (Some(_), "") if !m.grid_i.is_empty() => {
                return Err(fail(
                    "the scene is a garment: grid_i/grid_j need the panel they index".into(),
                ))
            }
            (Some(_), "") => None,
            (Some(g), name) => Some(g.panel(name).map_err(|e| fail(e.to_string()))?),
        };
        let mut v = Vec::with_capacity(m.grid_i.len());
        for (k, (&i, &j)) in m.grid_i.iter().zip(&m.grid_j).enumerate() {
            let (i, j) = (i as usize, j as usize);
            let at = match panel {
                Some(p) => p.vertex(i, j),
                None => sim.cloth.index(i, j),
            };
            v.push(at.map_err(|e| fail(format!("grid (i, j)[{k}] = ({i}, {j}): {e}")))?);
        }
        v
    };
    if vertices.is_empty() {
        return Err(fail("no vertices given".into()));
    }
    let check_len = |what: &str, len: usize| -> Result<(), String> {
        if len != 0 && len != vertices.len() {
            return Err(fail(format!(
                "{len} {what} for {} vertices (give one per vertex, or none)",
                vertices.len()
            )));
        }
        Ok(())
    };
    check_len("targets", m.targets.len())?;
    check_len("velocities", m.velocities.len())?;
    for (k, p) in m.targets.iter().enumerate() {
        limits::check_reach(&format!("targets[{k}]"), &p.vector(), sim.cloth.positions())
            .map_err(|e| fail(e.to_string()))?;
    }
    for (k, p) in m.velocities.iter().enumerate() {
        limits::check_speed(
            &format!("velocities[{k}]"),
            &p.vector(),
            MAX_PIN_SPEED,
            "m/s",
        )
        .map_err(|e| fail(e.to_string()))?;
    }
    let mut pins = sim.pins().as_slice().to_vec();
    // a target farther than one step at PIN_TRAVEL_SPEED is travelled to
    // at that speed (PinPath::travel)
    let at = |k: usize| -> PinPath {
        let here = sim.cloth.positions()[vertices[k]];
        let target = m.targets.get(k).map(|p| p.vector()).unwrap_or(here);
        let path = match m.velocities.get(k) {
            Some(v) if v.vector() != Vector3::zeros() => PinPath::Velocity {
                start: target,
                velocity: v.vector(),
                t0: sim.time,
            },
            _ => PinPath::Fixed(target),
        };
        path.travel(here, sim.time, sim.params().dt)
    };
    let verb = match m.operation {
        msgs::Pin::PIN => {
            for (k, &v) in vertices.iter().enumerate() {
                let path = at(k);
                match pins.iter_mut().find(|p| p.vertex == v) {
                    Some(p) => {
                        p.path = path;
                        p.release_at = None;
                    }
                    None => pins.push(Pin::new(v, path)),
                }
            }
            "pinned"
        }
        msgs::Pin::MOVE => {
            if m.targets.is_empty() {
                return Err(fail("MOVE needs targets".into()));
            }
            for (k, &v) in vertices.iter().enumerate() {
                let path = at(k);
                let p = pins.iter_mut().find(|p| p.vertex == v).ok_or_else(|| {
                    fail(format!("vertex {v} is not pinned (PIN it before MOVE)"))
                })?;
                p.path = path;
            }
            "moved"
        }
        msgs::Pin::RELEASE => {
            pins.retain(|p| !vertices.contains(&p.vertex));
            "released"
        }
        op => {
            return Err(fail(format!(
                "operation {op} unknown (PIN=0, MOVE=1, RELEASE=2, RELEASE_ALL=3)"
            )))
        }
    };
    sim.set_pins(pins).map_err(|e| fail(e.to_string()))?;
    Ok(format!("{verb} {} vertices", vertices.len()))
}

/// Keeps a running simulation stepping when a step fails: the pins and
/// obstacles as they were at the end of the last step that succeeded, and
/// the count of steps recovered.
///
/// A failed step changes neither the positions, the velocities nor the time
/// ([`Simulation::step`]); it has advanced the hysteresis memory to the
/// positions it started from, as the step that follows would (and a retry
/// does again): the last good state is the state the simulation is in. [`Recovery::step`]
/// retries from it, first without the pins and obstacles changed since the
/// last good step (the messages that drove the failure), then with the
/// velocities set to zero (the cloth at rest where it is). Every try steps
/// through the run interface ([`Recovery::run`]).
#[derive(Debug, Default)]
pub struct Recovery {
    inputs: Option<(Set<Pin>, Set<Obstacle>, ObstacleRegistry)>,
    /// Steps that failed and were recovered.
    pub recovered: u64,
    /// The node's steps and their costs.
    pub run: crate::run::Run,
}

/// A step taken by [`Recovery::step`].
#[derive(Debug)]
pub enum Stepped {
    Ok(crate::solver::StepStats),
    /// The step failed (`error`) and was taken again after `undone`.
    Recovered {
        stats: crate::solver::StepStats,
        error: String,
        undone: String,
    },
}

impl Recovery {
    /// Call before a message changes the pins or the obstacles: remembers
    /// them as the last good step left them (once between two steps).
    pub fn before_change(&mut self, sim: &Simulation, registry: &ObstacleRegistry) {
        if self.inputs.is_none() {
            self.inputs = Some((
                sim.pins().clone(),
                sim.obstacles().clone(),
                registry.clone(),
            ));
        }
    }

    /// Forgets the pins and obstacles remembered (a new scene was loaded).
    pub fn forget(&mut self) {
        self.inputs = None;
    }

    /// One step of `sim`; if it fails, the recoveries above in turn. An
    /// error (every retry failed too) leaves the last good state.
    pub fn step(
        &mut self,
        sim: &mut Simulation,
        registry: &mut ObstacleRegistry,
    ) -> Result<Stepped, String> {
        let first = match self.run.step(sim) {
            Ok(st) => {
                self.inputs = None;
                return Ok(Stepped::Ok(st));
            }
            Err(e) => e.error,
        };
        let mut last = first.clone();
        if let Some((pins, obstacles, reg)) = self.inputs.take() {
            let what = format!(
                "undid the pins and obstacles messages since the last good step \
                 ({} → {} pins, {} → {} obstacles)",
                sim.pins().len(),
                pins.len(),
                sim.obstacles().len(),
                obstacles.len()
            );
            sim.set_pin_set(pins)
                .map_err(|e| format!("{first}; {e:#}"))?;
            sim.set_obstacles(obstacles);
            *registry = reg;
            match self.run.step(sim) {
                Ok(stats) => return Ok(self.recovered(stats, first, what)),
                Err(e) => last = e.error,
            }
        }
        sim.cloth.stop();
        match self.run.step(sim) {
            Ok(stats) => {
                let what = "set every velocity to zero (the cloth at rest where it was)";
                Ok(self.recovered(stats, first, what.into()))
            }
            Err(e) => Err(format!(
                "{first}; not recovered: {last}; with the velocities set to zero: {}",
                e.error
            )),
        }
    }

    fn recovered(
        &mut self,
        stats: crate::solver::StepStats,
        error: String,
        undone: String,
    ) -> Stepped {
        self.recovered += 1;
        Stepped::Recovered {
            stats,
            error,
            undone,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Overrides, Scene};

    fn sim() -> Simulation {
        sim_at(0.1)
    }

    fn sim_at(spacing: f64) -> Simulation {
        let p =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/scenes/table_drape.yaml");
        Scene::load(&p)
            .unwrap()
            .build(&Overrides {
                spacing: Some(spacing),
                ..Default::default()
            })
            .unwrap()
    }

    fn pose_at(x: f64, y: f64, z: f64) -> msgs::Pose {
        msgs::Pose {
            position: msgs::Point { x, y, z },
            ..Default::default()
        }
    }

    #[test]
    fn obstacle_add_move_remove_with_parts() {
        let mut s = sim();
        let mut reg = ObstacleRegistry::from_sim(&s);
        let n0 = s.obstacles().len();
        let mut m = msgs::Obstacle {
            id: "gripper".into(),
            pose: pose_at(0.0, 0.0, 1.0),
            primitives: vec![
                msgs::SolidPrimitive {
                    type_: msgs::SolidPrimitive::SPHERE,
                    dimensions: vec![0.02],
                    ..Default::default()
                },
                msgs::SolidPrimitive {
                    type_: msgs::SolidPrimitive::BOX,
                    dimensions: vec![0.02, 0.02, 0.1],
                    ..Default::default()
                },
            ],
            primitive_poses: vec![pose_at(0.1, 0.0, 0.0), pose_at(-0.1, 0.0, 0.0)],
            thickness: f64::NAN,
            friction: f64::NAN,
            operation: msgs::Obstacle::ADD,
            ..Default::default()
        };
        apply_obstacle(&mut s, &mut reg, &m, "world", 1000).unwrap();
        assert_eq!(s.obstacles().len(), n0 + 2);
        let part = s.obstacles().iter().find(|o| o.id == "gripper#0").unwrap();
        assert!((part.pose.translation.vector - Vector3::new(0.1, 0.0, 1.0)).norm() < 1e-12);
        assert_eq!(part.thickness, DEFAULT_OBSTACLE_THICKNESS);
        // move the frame up 0.5 m while turning about z: parts follow, with
        // the velocity of their own origin
        m.operation = msgs::Obstacle::MOVE;
        m.pose = pose_at(0.0, 0.0, 1.5);
        m.velocity.angular.z = 2.0;
        apply_obstacle(&mut s, &mut reg, &m, "world", 1000).unwrap();
        let part = s.obstacles().iter().find(|o| o.id == "gripper#1").unwrap();
        assert!((part.pose.translation.vector - Vector3::new(-0.1, 0.0, 1.5)).norm() < 1e-12);
        assert!((part.linear_velocity - Vector3::new(0.0, -0.2, 0.0)).norm() < 1e-12);
        m.operation = msgs::Obstacle::REMOVE;
        apply_obstacle(&mut s, &mut reg, &m, "world", 1000).unwrap();
        assert_eq!(s.obstacles().len(), n0);
        assert!(apply_obstacle(&mut s, &mut reg, &m, "world", 1000)
            .unwrap_err()
            .contains("no such obstacle"));
    }

    #[test]
    fn bad_obstacles_change_nothing() {
        let mut s = sim();
        let mut reg = ObstacleRegistry::from_sim(&s);
        let n0 = s.obstacles().len();
        let mesh = msgs::Obstacle {
            id: "m".into(),
            meshes: vec![msgs::Mesh {
                triangles: vec![msgs::MeshTriangle {
                    vertex_indices: [0, 1, 7],
                }],
                vertices: vec![msgs::Point::default(); 3],
            }],
            mesh_poses: vec![msgs::Pose::default()],
            ..Default::default()
        };
        let e = apply_obstacle(&mut s, &mut reg, &mesh, "world", 1000).unwrap_err();
        assert!(e.contains("vertex 7"), "{e}");
        let e = apply_obstacle(&mut s, &mut reg, &mesh, "world", 0).unwrap_err();
        assert!(e.contains("max_mesh_triangles = 0"), "{e}");
        let mut nan = mesh.clone();
        nan.meshes.clear();
        nan.mesh_poses.clear();
        nan.primitives = vec![msgs::SolidPrimitive {
            type_: msgs::SolidPrimitive::BOX,
            dimensions: vec![0.1, f64::NAN, 0.1],
            ..Default::default()
        }];
        nan.primitive_poses = vec![msgs::Pose::default()];
        assert!(apply_obstacle(&mut s, &mut reg, &nan, "world", 1000)
            .unwrap_err()
            .contains("primitives[0]"));
        let mut q = nan.clone();
        q.primitives[0].dimensions = vec![0.1, 0.1, 0.1];
        q.pose.orientation.w = 0.0;
        assert!(apply_obstacle(&mut s, &mut reg, &q, "world", 1000)
            .unwrap_err()
            .contains("quaternion"));
        assert_eq!(s.obstacles().len(), n0);
    }

    #[test]
    fn pins_pin_move_release() {
        let mut s = sim();
        let n = s.cloth.len();
        let corner = s.cloth.index(s.cloth.nx - 1, 0).unwrap();
        let mut m = msgs::Pin {
            operation: msgs::Pin::PIN,
            grid_i: vec![(s.cloth.nx - 1) as u32],
            grid_j: vec![0],
            ..Default::default()
        };
        apply_pin(&mut s, None, &m, "world").unwrap();
        assert_eq!(
            s.pins().last().unwrap().path,
            PinPath::Fixed(s.cloth.positions()[corner])
        );
        m.operation = msgs::Pin::MOVE;
        m.targets = vec![msgs::Point {
            x: 0.0,
            y: 0.0,
            z: 2.0,
        }];
        m.velocities = vec![msgs::Vector3 {
            x: 0.0,
            y: 0.0,
            z: 0.1,
        }];
        apply_pin(&mut s, None, &m, "world").unwrap();
        // the target is far: the pin travels there at PIN_TRAVEL_SPEED, then
        // moves on with the velocity
        let d = (Vector3::new(0.0, 0.0, 2.0) - s.cloth.positions()[corner]).norm();
        let arrive = s.time + d / limits::PIN_TRAVEL_SPEED;
        let (p, v) = s.pins().last().unwrap().path.at(arrive + 1.0);
        assert!((p - Vector3::new(0.0, 0.0, 2.1)).norm() < 1e-12 && v.z == 0.1);
        let pinned = s.pins().len();
        // errors: vertex out of range, unpinned MOVE, length mismatch, NaN
        let bad = msgs::Pin {
            operation: msgs::Pin::PIN,
            vertices: vec![n as u32],
            ..Default::default()
        };
        assert!(apply_pin(&mut s, None, &bad, "world")
            .unwrap_err()
            .contains("out of range"));
        let bad = msgs::Pin {
            operation: msgs::Pin::MOVE,
            vertices: vec![0],
            targets: vec![msgs::Point::default()],
            ..Default::default()
        };
        assert!(apply_pin(&mut s, None, &bad, "world")
            .unwrap_err()
            .contains("not pinned"));
        let bad = msgs::Pin {
            operation: msgs::Pin::PIN,
            vertices: vec![0, 1],
            targets: vec![msgs::Point::default()],
            ..Default::default()
        };
        assert!(apply_pin(&mut s, None, &bad, "world")
            .unwrap_err()
            .contains("1 targets for 2 vertices"));
        let bad = msgs::Pin {
            operation: msgs::Pin::PIN,
            grid_i: vec![0],
            grid_j: vec![9999],
            ..Default::default()
        };
        assert!(apply_pin(&mut s, None, &bad, "world")
            .unwrap_err()
            .contains("grid (i, j)[0]"));
        assert_eq!(s.pins().len(), pinned);
        m.operation = msgs::Pin::RELEASE;
        apply_pin(&mut s, None, &m, "world").unwrap();
        assert_eq!(s.pins().len(), pinned - 1);
    }

    /// Steps `n` times; every step succeeds and leaves finite positions.
    fn steps_ok(s: &mut Simulation, n: usize) {
        for k in 0..n {
            if let Err(e) = s.step() {
                panic!("step {k} failed: {e:#}");
            }
            assert!(
                s.cloth
                    .positions()
                    .iter()
                    .all(|p| p.iter().all(|c| c.is_finite())),
                "non-finite position after step {k}"
            );
        }
    }

    fn pin_msg(op: u8, v: u32, target: Option<[f64; 3]>, vel: Option<[f64; 3]>) -> msgs::Pin {
        msgs::Pin {
            operation: op,
            vertices: vec![v],
            targets: target
                .map(|[x, y, z]| vec![msgs::Point { x, y, z }])
                .unwrap_or_default(),
            velocities: vel
                .map(|[x, y, z]| vec![msgs::Vector3 { x, y, z }])
                .unwrap_or_default(),
            ..Default::default()
        }
    }

    #[test]
    fn implausible_pins_are_refused_and_far_targets_travelled() {
        // refused: millimetres sent as metres, 1e200, 1e5 m/s, 1e300 m/s;
        // the simulation then steps on unchanged
        let mut s = sim();
        let n_pins = s.pins().len();
        for (m, why) in [
            (
                pin_msg(msgs::Pin::PIN, 0, Some([500.0, 0.0, 1000.0]), None),
                "targets[0]",
            ),
            (
                pin_msg(msgs::Pin::PIN, 0, Some([1e200, 0.0, 0.0]), None),
                "targets[0]",
            ),
            (
                pin_msg(msgs::Pin::PIN, 0, None, Some([1e5, 0.0, 0.0])),
                "velocities[0]",
            ),
            (
                pin_msg(msgs::Pin::PIN, 0, None, Some([0.0, 1e300, 0.0])),
                "velocities[0]",
            ),
        ] {
            let e = apply_pin(&mut s, None, &m, "world").unwrap_err();
            assert!(e.contains(why), "{e}");
            assert_eq!(s.pins().len(), n_pins);
        }
        steps_ok(&mut s, 20);
        // a target 1.5 m above a corner held by another pin on the opposite
        // corner: accepted, reached at a bounded speed, every step succeeds
        let mut s = sim();
        let a = s.cloth.index(0, 0).unwrap();
        let b = s.cloth.index(s.cloth.nx - 1, s.cloth.ny - 1).unwrap();
        apply_pin(
            &mut s,
            None,
            &pin_msg(msgs::Pin::PIN, b as u32, None, None),
            "world",
        )
        .unwrap();
        let x0 = s.cloth.positions()[a];
        let goal = x0 + Vector3::new(0.0, 0.0, 1.5);
        let target = Some([goal.x, goal.y, goal.z]);
        apply_pin(
            &mut s,
            None,
            &pin_msg(msgs::Pin::PIN, a as u32, target, None),
            "world",
        )
        .unwrap();
        let dt = s.params().dt;
        let mut fastest: f64 = 0.0;
        let mut last = s.cloth.positions()[a];
        let steps = (1.5 / 2.0 / dt).ceil() as usize + 50;
        for k in 0..steps {
            if let Err(e) = s.step() {
                panic!("step {k} failed: {e:#}");
            }
            assert!(s
                .cloth
                .positions()
                .iter()
                .all(|p| p.iter().all(|c| c.is_finite())));
            fastest = fastest.max((s.cloth.positions()[a] - last).norm() / dt);
            last = s.cloth.positions()[a];
        }
        assert!(
            (s.cloth.positions()[a] - goal).norm() < 1e-9,
            "{:?}",
            s.cloth.positions()[a]
        );
        assert!(fastest <= 2.0 + 1e-9, "pin moved at {fastest} m/s");
    }

    #[test]
    fn pin_at_a_far_target_with_velocity_steps() {
        // 3 m from the vertex (within reach of the cloth's box), moving,
        // while the opposite corner is held (the node's default spacing)
        let mut s = sim_at(0.05);
        let a = s.cloth.index(0, 0).unwrap();
        let b = s.cloth.index(s.cloth.nx - 1, s.cloth.ny - 1).unwrap();
        apply_pin(
            &mut s,
            None,
            &pin_msg(msgs::Pin::PIN, b as u32, None, None),
            "world",
        )
        .unwrap();
        let g = s.cloth.positions()[a] + Vector3::new(2.0, 2.0, 1.0);
        let m = pin_msg(
            msgs::Pin::PIN,
            a as u32,
            Some([g.x, g.y, g.z]),
            Some([0.5, 0.0, 0.0]),
        );
        apply_pin(&mut s, None, &m, "world").unwrap();
        steps_ok(&mut s, 1700);
        let (p, v) = s.pins().last().unwrap().path.at(s.time);
        assert!(
            (s.cloth.positions()[a] - p).norm() < 1e-9 && v.x == 0.5,
            "{p:?} {v:?}"
        );
    }

    fn sphere(id: &str, r: f64, at: Vector3<f64>) -> msgs::Obstacle {
        msgs::Obstacle {
            id: id.into(),
            pose: pose_at(at.x, at.y, at.z),
            primitives: vec![msgs::SolidPrimitive {
                type_: msgs::SolidPrimitive::SPHERE,
                dimensions: vec![r],
                ..Default::default()
            }],
            primitive_poses: vec![msgs::Pose::default()],
            thickness: f64::NAN,
            friction: f64::NAN,
            operation: msgs::Obstacle::ADD,
            ..Default::default()
        }
    }

    #[test]
    fn implausible_obstacles_are_refused() {
        let mut s = sim();
        let mut reg = ObstacleRegistry::from_sim(&s);
        let n0 = s.obstacles().len();
        let c = s.cloth.positions()[s.cloth.len() / 2];
        // a 0.3 m sphere around the cloth's middle, a sphere of radius
        // 1e300, one 1 km away, one moving at 1e5 m/s
        let around = sphere("around", 0.3, c);
        let e = apply_obstacle(&mut s, &mut reg, &around, "world", 1000).unwrap_err();
        assert!(
            e.contains("overlaps the cloth") && e.contains("\"around\""),
            "{e}"
        );
        let e =
            apply_obstacle(&mut s, &mut reg, &sphere("big", 1e300, c), "world", 1000).unwrap_err();
        assert!(e.contains("dimensions[0]"), "{e}");
        let far = sphere("far", 0.1, c + Vector3::new(1000.0, 0.0, 0.0));
        let e = apply_obstacle(&mut s, &mut reg, &far, "world", 1000).unwrap_err();
        assert!(e.contains("pose.position"), "{e}");
        let mut fast = sphere("fast", 0.1, c + Vector3::new(0.0, 0.0, 0.5));
        fast.velocity.linear.x = 1e5;
        let e = apply_obstacle(&mut s, &mut reg, &fast, "world", 1000).unwrap_err();
        assert!(e.contains("velocity.linear"), "{e}");
        assert_eq!(s.obstacles().len(), n0);
        // a sphere beside the cloth, then moved onto it: the MOVE is refused
        // and the sphere stays where it was
        let beside = sphere("beside", 0.1, c + Vector3::new(0.0, 0.0, 0.5));
        apply_obstacle(&mut s, &mut reg, &beside, "world", 1000).unwrap();
        let mut onto = beside.clone();
        onto.operation = msgs::Obstacle::MOVE;
        onto.pose = pose_at(c.x, c.y, c.z);
        let e = apply_obstacle(&mut s, &mut reg, &onto, "world", 1000).unwrap_err();
        assert!(e.contains("overlaps the cloth"), "{e}");
        let o = s.obstacles().iter().find(|o| o.id == "beside").unwrap();
        assert!((o.pose.translation.vector - (c + Vector3::new(0.0, 0.0, 0.5))).norm() < 1e-12);
        steps_ok(&mut s, 20);
    }

    /// A step that fails is recovered: a pin that slipped past the limits
    /// (an infinite target: forces overflow) is undone with the other
    /// messages since the last good step; a state that breaks the step (a
    /// vertex moving infinitely fast) is taken at rest. Each failure is counted, the
    /// simulation keeps stepping, and the failed step changed nothing.
    #[test]
    fn a_failed_step_is_recovered_and_counted() {
        let mut s = sim();
        let mut reg = ObstacleRegistry::from_sim(&s);
        let mut rec = Recovery::default();
        for _ in 0..3 {
            assert!(matches!(rec.step(&mut s, &mut reg), Ok(Stepped::Ok(_))));
        }
        let pins = s.pins().clone();
        let obstacles = s.obstacles().len();
        // an obstacle added (a plausible message) and a pin at a target no
        // message may give (not finite), since the last good step
        rec.before_change(&s, &reg);
        let c = s.cloth.positions()[s.cloth.len() / 2];
        apply_obstacle(
            &mut s,
            &mut reg,
            &sphere("ball", 0.05, c + Vector3::new(0.0, 0.0, -0.3)),
            "world",
            100,
        )
        .unwrap();
        assert_eq!(s.obstacles().len(), obstacles + 1);
        let mut bad = s.pins().to_vec();
        bad.push(Pin::new(
            0,
            PinPath::Fixed(Vector3::new(f64::INFINITY, 0.0, 0.0)),
        ));
        s.set_pins(bad).unwrap();
        let before = (
            s.cloth.positions().to_vec(),
            s.cloth.velocities().to_vec(),
            s.time,
            s.steps,
        );
        // the step alone fails and changes no position, velocity or time;
        // the hysteresis memory is where the step starts from, and a retry
        // leaves it there
        let e = s.step().unwrap_err();
        assert!(format!("{e:#}").contains("diverged at vertex 0"), "{e:#}");
        assert_eq!(
            (
                s.cloth.positions().to_vec(),
                s.cloth.velocities().to_vec(),
                s.time,
                s.steps
            ),
            before
        );
        let memory = s.cloth.tension_state.clone();
        assert!(s.step().is_err());
        for (a, b) in s.cloth.tension_state.iter().zip(&memory) {
            assert_eq!((a.x, a.dir), (b.x, b.dir));
            assert!((a.sp - b.sp).abs() <= 1e-12 * b.sp.abs(), "{a:?} {b:?}");
        }
        match rec.step(&mut s, &mut reg) {
            Ok(Stepped::Recovered { error, undone, .. }) => {
                assert!(error.contains("vertex 0"), "{error}");
                assert!(undone.contains("pins and obstacles"), "{undone}");
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(rec.recovered, 1);
        assert_eq!(s.steps, before.3 + 1);
        assert_eq!(s.pins(), &pins);
        assert_eq!(s.obstacles().len(), obstacles);
        // the registry was undone with the obstacles: "ball" is unknown again
        let mut gone = sphere("ball", 0.05, c);
        gone.operation = msgs::Obstacle::REMOVE;
        assert!(apply_obstacle(&mut s, &mut reg, &gone, "world", 100).is_err());
        steps_ok(&mut s, 3);
        // a broken state, no message since: the cloth is taken at rest
        // (a velocity that overflows the first position it moves)
        let mut v = s.cloth.velocities().to_vec();
        v[5] = Vector3::new(0.0, 0.0, 1e308);
        s.cloth.set_velocities(&v).unwrap();
        let steps = s.steps;
        match rec.step(&mut s, &mut reg) {
            Ok(Stepped::Recovered { undone, .. }) => {
                assert!(undone.contains("velocity to zero"), "{undone}")
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(rec.recovered, 2);
        assert_eq!(s.steps, steps + 1);
        assert!(s.cloth.velocities().iter().all(|v| v.norm() < 1.0));
        assert!(matches!(rec.step(&mut s, &mut reg), Ok(Stepped::Ok(_))));
        assert_eq!(rec.recovered, 2);
    }
}
