//! One sensor's image cut from an equirectangular panorama.
//!
//! In: the panorama (RGB), where it was taken ([`Pano`]), the rig's pose there and one sensor.
//! Out: the sensor's image: each pixel the mean of 2 × 2 rays over its area (so that a sensor
//! coarser than the photo does not alias), each ray looked up bilinearly, wrapping around the
//! panorama's seam. Pixels whose ray the lens cannot form (outside a fisheye's circle) are black.

use crate::tour::Pano;
use image::{Rgb, RgbImage};
use nalgebra::Point2;
use omnitrack::geometry::Pose;
use omnitrack::rig::Sensor;

pub fn sensor_image(photo: &RgbImage, pano: &Pano, t_world_rig: &Pose, sensor: &Sensor) -> RgbImage {
    let rotation = t_world_rig.rotation * sensor.t_rig_sensor.rotation;
    let (w, h) = photo.dimensions();
    let mut out = RgbImage::new(sensor.width, sensor.height);
    for (x, y, px) in out.enumerate_pixels_mut() {
        let mut sum = [0.0f64; 3];
        let mut rays = 0;
        for (dx, dy) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
            let Some(ray) = sensor.lens.unproject(&Point2::new(x as f64 + dx, y as f64 + dy)) else {
                continue;
            };
            let (u, v) = pano.pixel_of(&(rotation * ray.into_inner()), w, h);
            let c = bilinear(photo, u, v);
            for k in 0..3 {
                sum[k] += c[k];
            }
            rays += 1;
        }
        if rays > 0 {
            *px = Rgb(sum.map(|s| (s / rays as f64).round().clamp(0.0, 255.0) as u8));
        }
    }
    out
}

/// The photo at (u, v), wrapping in u (azimuth) and clamping in v.
fn bilinear(photo: &RgbImage, u: f64, v: f64) -> [f64; 3] {
    let (w, h) = photo.dimensions();
    let (u0, v0) = (u.floor(), v.floor());
    let (fu, fv) = (u - u0, v - v0);
    let col = |c: f64| (c as i64).rem_euclid(w as i64) as u32;
    let row = |r: f64| (r as i64).clamp(0, h as i64 - 1) as u32;
    let mut out = [0.0; 3];
    for (du, dv, weight) in [
        (0.0, 0.0, (1.0 - fu) * (1.0 - fv)),
        (1.0, 0.0, fu * (1.0 - fv)),
        (0.0, 1.0, (1.0 - fu) * fv),
        (1.0, 1.0, fu * fv),
    ] {
        let p = photo.get_pixel(col(u0 + du), row(v0 + dv));
        for k in 0..3 {
            out[k] += weight * p[k] as f64;
        }
    }
    out
}
