//! Building one cycle's messages for an agent: the images as PNG, the pose, rewards, the
//! statuses of its actions.

use super::*;

impl LegacyHost {
    pub(super) fn encode_png(
        &mut self,
        slot: usize,
        which: usize,
        desc: &ImageDesc,
        payload: &[u8],
    ) {
        let started = Instant::now();
        let out = &mut self.slots[slot].png[which];
        out.clear();
        let start = desc.offset as usize;
        let data = payload.get(start..start + desc.len as usize).unwrap_or(&[]);
        let color = match desc.pixel_format() {
            Some(PixelFormat::Rgba8) => png::ColorType::Rgba,
            Some(PixelFormat::Gray8) => png::ColorType::Grayscale,
            _ => png::ColorType::Rgb,
        };
        let mut enc = png::Encoder::new(&mut *out, desc.width_px, desc.height_px);
        enc.set_color(color);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(match self.png {
            PngCompression::Fastest => png::Compression::Fastest,
            PngCompression::Fast => png::Compression::Fast,
            PngCompression::Balanced => png::Compression::Balanced,
            PngCompression::High => png::Compression::High,
        });
        let r = enc
            .write_header()
            .and_then(|mut w| w.write_image_data(data).and_then(|()| w.finish()));
        if let Err(e) = r {
            // Only a table/size mismatch can get here, a bug: an empty image tells the
            // client nothing is there rather than nothing at all.
            warn!(agent = self.slots[slot].id, "PNG encoding failed: {e}");
            self.slots[slot].png[which].clear();
        }
        self.stats.png_images += 1;
        self.stats.png_time += started.elapsed();
    }

    /// Writes one cycle's messages for slot `slot` into its `out` buffer.
    pub(super) fn build_cycle(&mut self, slot: usize, header: &SensorHeader, payload: &[u8]) {
        let dialect = match &self.slots[slot].conn {
            Some(c) => c.dialect,
            None => return,
        };
        let mut out = std::mem::take(&mut self.slots[slot].out);
        out.clear();
        // 1. Statuses and collisions of the last cycle's commands.
        self.push_events(slot, header, &mut out);
        // 2. Images.
        self.push_images(slot, dialect, header, payload, &mut out);
        // 3. Grid position; 4. optional sensors.
        self.push_sensors(dialect, header, &mut out);
        // 5. StartSync (sync mode); 6. a Debug trailer naming the cycle.
        if self.sync_mode {
            codec::push_message(&mut out, field::START_SYNC, &codec::Empty {});
        }
        codec::push_debug(&mut out, &format!("vrsync cycle {}", header.cycle));
        self.slots[slot].out = out;
    }

    /// The statuses and collisions of slot `slot`'s commands not sent yet; a command the
    /// simulator rejected last cycle (no status for it) ends Aborted.
    fn push_events(&mut self, slot: usize, header: &SensorHeader, out: &mut Vec<u8>) {
        let s = &mut self.slots[slot];
        if header.previous_rejected > 0 && s.applied_cycle.is_some_and(|c| c + 1 == header.cycle) {
            // The simulator rejected some of the commands handed over last cycle and
            // reports no status for them: those without one end Aborted.
            for &id in &s.applied {
                if !header.statuses().iter().any(|st| st.action_id == id) {
                    push_status(out, id, ActionState::Aborted);
                    self.stats.commands_rejected += 1;
                }
            }
        }
        // Events the host repeats (not acknowledged yet) went to the client already.
        let seen = s.last_event_seq;
        s.last_event_seq = header
            .statuses()
            .iter()
            .map(|st| st.seq)
            .chain(header.collisions().iter().map(|c| c.seq))
            .fold(seen, u64::max);
        for c in header.collisions().iter().filter(|c| c.seq > seen) {
            codec::push_message(
                out,
                field::COLLISION,
                &codec::Collision {
                    action_id: Some(c.action_id as i32),
                    collider_id: Some(c.collider_id as i32),
                },
            );
        }
        for st in header.statuses().iter().filter(|st| st.seq > seen) {
            if st.action_id != RESET_ACTION_ID {
                codec::push_message(
                    out,
                    field::ACTION_STATUS,
                    &ActionStatus {
                        action_id: Some(st.action_id as i32),
                        status: Some(st.state as i32),
                    },
                );
            }
        }
    }

    /// The left, right and (burkhardt) main images as PNG, each camera encoded once.
    fn push_images(
        &mut self,
        slot: usize,
        dialect: Dialect,
        header: &SensorHeader,
        payload: &[u8],
        out: &mut Vec<u8>,
    ) {
        let descs = header.image_descs();
        let pick = |name: &str, index: usize| {
            descs
                .iter()
                .position(|d| d.name() == name)
                .or_else(|| (index < descs.len()).then_some(index))
        };
        let left = pick("left", 0);
        let right = pick("right", 1).or(left);
        let main = match dialect {
            Dialect::Burkhardt => pick("main", 2).or(left),
            Dialect::Vrnew => None,
        };
        let mut which_of = [usize::MAX; 3];
        for (k, cam) in [left, right, main].into_iter().enumerate() {
            let Some(cam) = cam else { continue };
            // An image used twice is encoded once.
            if let Some(j) = (0..k).find(|&j| [left, right, main][j] == Some(cam)) {
                which_of[k] = which_of[j];
                continue;
            }
            which_of[k] = k;
            let desc = descs[cam];
            self.encode_png(slot, k, &desc, payload);
        }
        let s = &mut self.slots[slot];
        let png = |k: usize| -> &[u8] { s.png.get(which_of[k]).map_or(&[], Vec::as_slice) };
        codec::push_images(out, png(0), png(1), main.is_some().then(|| png(2)));
    }

    /// GridPosition, a non-zero reward, and EyePosition and HeadMotion if configured.
    fn push_sensors(&self, dialect: Dialect, header: &SensorHeader, out: &mut Vec<u8>) {
        let g = &header.grid;
        codec::push_message(
            out,
            field::GRID_POSITION,
            &GridPosition {
                x: Some(g.position[0]),
                y: Some(g.position[1]),
                z: Some(g.position[2]),
                rotation_x: Some(g.rotation_deg[0]),
                rotation_y: Some(g.rotation_deg[1]),
                rotation_z: Some(g.rotation_deg[2]),
            },
        );
        if header.reward != 0.0 {
            codec::push_message(
                out,
                field::REWARD,
                &Reward {
                    reward: Some(header.reward),
                },
            );
        }
        if self.send_eye {
            let e = &header.eye;
            codec::push_message(
                out,
                field::EYE_POSITION,
                &EyePosition {
                    x: Some(e.rotation_deg[0]),
                    y: Some(e.rotation_deg[1]),
                    z: Some(e.rotation_deg[2]),
                    vx: Some(e.rotation_velocity_deg[0]),
                    vy: Some(e.rotation_velocity_deg[1]),
                    vz: Some(e.rotation_velocity_deg[2]),
                },
            );
        }
        if self.send_head {
            let h = &header.head_motion;
            codec::push_message(
                out,
                dialect.head_motion_field(),
                &HeadMotion {
                    vx: Some(h.velocity[0]),
                    vy: Some(h.velocity[1]),
                    vz: Some(h.velocity[2]),
                    ax: Some(h.acceleration[0]),
                    ay: Some(h.acceleration[1]),
                    az: Some(h.acceleration[2]),
                    rvx: Some(h.angular_velocity_deg[0]),
                    rvy: Some(h.angular_velocity_deg[1]),
                    rvz: Some(h.angular_velocity_deg[2]),
                    rax: Some(h.angular_acceleration_deg[0]),
                    ray: Some(h.angular_acceleration_deg[1]),
                    raz: Some(h.angular_acceleration_deg[2]),
                },
            );
        }
    }
}

/// Appends an ActionExecutationStatus frame.
pub(super) fn push_status(out: &mut Vec<u8>, action_id: u32, state: ActionState) {
    codec::push_message(
        out,
        field::ACTION_STATUS,
        &ActionStatus {
            action_id: Some(action_id as i32),
            status: Some(state as i32),
        },
    );
}
