//! [`Renderer`]: a camera and its buffers, drawing a [`Scene`] into RGB, depth and
//! segmentation images.

use crate::camera::{Camera, CameraConfig};
use crate::error::Result;
use crate::raster::Raster;
use crate::scene_mesh::SceneMeshes;
use crate::segment::Segment;
use fairgrasp_sim::rapier3d::math::Vector;
use fairgrasp_sim::scene::Scene;

/// sRGB of pixels that show nothing (a pale grey-blue wall).
pub const BACKGROUND_RGB: [u8; 3] = [205, 214, 224];

/// How a frame is lit and coloured beyond the scene's own colours: what visual domain
/// randomisation varies. The default draws the scene as designed.
#[derive(Clone, Debug, PartialEq)]
pub struct Look {
    /// World direction toward the light; `None`: above and behind the camera.
    pub light: Option<[f32; 3]>,
    /// Scales every lit colour.
    pub brightness: f32,
    /// sRGB of pixels that show nothing.
    pub background: [u8; 3],
    /// Multiplies the table's linear colour, channel by channel.
    pub table_tint: [f32; 3],
    /// Multiplies the objects' and bins' linear colours.
    pub object_tint: [f32; 3],
    /// Multiplies the robot's linear colours.
    pub robot_tint: [f32; 3],
}

impl Default for Look {
    fn default() -> Self {
        Self {
            light: None,
            brightness: 1.0,
            background: BACKGROUND_RGB,
            table_tint: [1.0; 3],
            object_tint: [1.0; 3],
            robot_tint: [1.0; 3],
        }
    }
}

/// Renders one scene from one camera. Built for a scene ([`Renderer::new`]): it keeps that
/// scene's robot meshes, so render scenes with the same robot description only.
pub struct Renderer {
    camera: Camera,
    meshes: SceneMeshes,
    raster: Raster,
    depth: Vec<f32>,
    look: Look,
}

impl Renderer {
    /// Tessellates the scene's robot and sets up the camera's buffers.
    pub fn new(scene: &Scene, camera: Camera) -> Result<Self> {
        Ok(Self {
            meshes: SceneMeshes::new(scene)?,
            raster: Raster::new(camera.width(), camera.height()),
            depth: Vec::new(),
            look: Look::default(),
            camera,
        })
    }

    /// [`Self::new`] from camera settings (checked).
    pub fn with_config(scene: &Scene, config: CameraConfig) -> Result<Self> {
        Self::new(scene, Camera::new(config)?)
    }

    /// The camera it draws from.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// How frames are lit and coloured from now on.
    pub fn set_look(&mut self, look: Look) {
        self.look = look;
    }

    /// How frames are lit and coloured.
    pub fn look(&self) -> &Look {
        &self.look
    }

    /// Changes the camera (the buffers follow its size).
    pub fn set_camera(&mut self, camera: Camera) {
        if (camera.width(), camera.height()) != (self.camera.width(), self.camera.height()) {
            self.raster = Raster::new(camera.width(), camera.height());
        }
        self.camera = camera;
    }

    /// Draws the scene's current state; read the images with [`Self::rgb`], [`Self::depth`]
    /// and [`Self::segmentation`].
    pub fn render(&mut self, scene: &Scene) -> Result<()> {
        let look = &self.look;
        self.raster.clear(look.background);
        let light_world = match look.light {
            Some(toward) => Vector::from(toward).normalize(),
            // Light from above and behind the camera, so faces toward the viewer are lit.
            None => {
                let c = self.camera.config();
                let back = (Vector::from(c.eye) - Vector::from(c.target)).normalize();
                (back + Vector::new(0.0, 0.0, 1.5)).normalize()
            }
        };
        // The rasteriser wants the direction toward the light in the camera frame.
        let light = self.camera.direction_to_camera(light_world);
        for placed in self.meshes.placed(scene)? {
            let tint = match Segment::from_id(placed.id) {
                Segment::Table => look.table_tint,
                Segment::Object(_) | Segment::Bin(_) => look.object_tint,
                Segment::Link(_) => look.robot_tint,
                Segment::Background => [1.0; 3],
            };
            let colour = std::array::from_fn(|i| placed.colour[i] * tint[i] * look.brightness);
            self.raster.draw_mesh(
                &self.camera,
                light,
                &placed.pose,
                placed.mesh,
                colour,
                placed.id,
            );
        }
        self.raster.depth_into(self.camera.far(), &mut self.depth);
        Ok(())
    }

    /// Image width (pixels).
    pub fn width(&self) -> u32 {
        self.camera.width()
    }

    /// Image height (pixels).
    pub fn height(&self) -> u32 {
        self.camera.height()
    }

    /// The last frame's colours: `height × width × 3` bytes of sRGB, rows top to bottom.
    pub fn rgb(&self) -> &[u8] {
        &self.raster.rgb
    }

    /// The last frame's depth: `height × width` distances along the optical axis (m), the
    /// camera's `far` where nothing was hit. (Not the ray length: a flat wall facing the camera
    /// reads the same depth in every pixel.)
    pub fn depth(&self) -> &[f32] {
        &self.depth
    }

    /// The last frame's segmentation ids, `height × width` (see [`crate::segment`]).
    pub fn segmentation(&self) -> &[u16] {
        &self.raster.segmentation
    }

    /// The pixel index of `(column, row)`, for the slices above.
    pub fn index(&self, column: u32, row: u32) -> usize {
        row as usize * self.camera.width() as usize + column as usize
    }

    /// Triangles one frame of the scene's current state draws.
    pub fn triangles(&mut self, scene: &Scene) -> Result<usize> {
        let placed = self.meshes.placed(scene)?;
        Ok(placed.iter().map(|p| p.mesh.triangles.len()).sum())
    }

    /// Number of cached object and table meshes.
    pub fn cached_shapes(&self) -> usize {
        self.meshes.cached_shapes()
    }
}

/// What a segmentation id shows, by name: `background`, `table`, an object's or bin's name,
/// or `link:<name>`; `unknown:<id>` for an id the scene does not have.
pub fn segment_name(scene: &Scene, id: u16) -> String {
    match Segment::from_id(id) {
        Segment::Background => "background".into(),
        Segment::Table => "table".into(),
        Segment::Object(i) if i < scene.num_objects() => scene.object_name(i).to_string(),
        Segment::Bin(j) if j < scene.bins().len() => scene.bins()[j].name.clone(),
        Segment::Link(l) if l < scene.robot().model.links.len() => {
            format!("link:{}", scene.robot().model.links[l].name)
        }
        _ => format!("unknown:{id}"),
    }
}
