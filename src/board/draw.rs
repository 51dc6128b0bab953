//! Drawing `board.png`: the tags as the AprilTag library draws them (`apriltag_to_image`), the
//! window's outline, the reference patch and the scale bar, in whole pixels; and the PNG's
//! bytes with their print resolution (a `pHYs` chunk).

use super::BoardLayout;
use crate::load::image_io::{linear_to_srgb, srgb_to_linear};
use anyhow::{anyhow, Result};
use image::GrayImage;

/// The 8-bit sRGB grey that prints linear reflectance `r`.
pub fn patch_grey(r: f64) -> u8 {
    (linear_to_srgb(r.clamp(0.0, 1.0) as f32) * 255.0)
        .round()
        .clamp(0.0, 255.0) as u8
}

/// The linear reflectance the grey [`patch_grey`]`(r)` stands for.
pub fn printed_reflectance(r: f64) -> f64 {
    srgb_to_linear(patch_grey(r) as f32 / 255.0) as f64
}

/// Tag `id`'s cells as the AprilTag library draws them: `total` x `total` values (0 black,
/// 255 white), white ring included.
pub fn tag_cells(id: u32) -> Result<(usize, Vec<u8>)> {
    use apriltag_sys as sys;
    // SAFETY: the family is created and destroyed here; the image the library returns is read
    // within its width, height and stride and destroyed before returning.
    unsafe {
        let fam = sys::tag36h11_create();
        if fam.is_null() {
            return Err(anyhow!("the AprilTag library could not make the tag36h11 family"));
        }
        if id >= (*fam).ncodes {
            let n = (*fam).ncodes;
            sys::tag36h11_destroy(fam);
            return Err(anyhow!("tag36h11 has {n} tags; a board needs id {id}"));
        }
        let im = sys::apriltag_to_image(fam, id as i32);
        sys::tag36h11_destroy(fam);
        if im.is_null() {
            return Err(anyhow!("the AprilTag library could not draw tag {id}"));
        }
        let (w, h, stride) = ((*im).width as usize, (*im).height as usize, (*im).stride as usize);
        let mut cells = Vec::with_capacity(w * h);
        for y in 0..h {
            let row = std::slice::from_raw_parts((*im).buf.add(y * stride), w);
            cells.extend_from_slice(row);
        }
        sys::image_u8_destroy(im);
        Ok((w, cells))
    }
}

/// The board's picture (8-bit grey; white paper).
pub fn picture(layout: &BoardLayout) -> Result<GrayImage> {
    let [w, h] = layout.size_px;
    let mut img = GrayImage::from_pixel(w as u32, h as u32, image::Luma([255]));
    let mut fill = |r: [i64; 4], v: u8| {
        for y in r[1].max(0)..r[3].min(h) {
            for x in r[0].max(0)..r[2].min(w) {
                img.put_pixel(x as u32, y as u32, image::Luma([v]));
            }
        }
    };
    // the window's outline: a 0.5 mm mid-grey frame just outside it
    let t = (0.5 / layout.mm_per_px()).round().max(1.0) as i64;
    let [u0, v0, u1, v1] = layout.window_px;
    fill([u0 - t, v0 - t, u1 + t, v0], 128);
    fill([u0 - t, v1, u1 + t, v1 + t], 128);
    fill([u0 - t, v0, u0, v1], 128);
    fill([u1, v0, u1 + t, v1], 128);
    fill(layout.patch_px, patch_grey(layout.spec.patch_reflectance));
    fill(layout.bar_px, 0);
    for &tick in &layout.ticks_px {
        fill(tick, 0);
    }
    let c = layout.cell_px;
    for &(id, [u, v]) in &layout.markers {
        let (n, cells) = tag_cells(id)?;
        // the library's image has the white ring around the 8-cell black border
        let ring = (n as i64 - super::TAG_CELLS) / 2;
        for (k, &value) in cells.iter().enumerate() {
            let (cx, cy) = ((k % n) as i64 - ring, (k / n) as i64 - ring);
            let (x0, y0) = (u + cx * c, v + cy * c);
            fill([x0, y0, x0 + c, y0 + c], value);
        }
    }
    Ok(img)
}

/// `img` as PNG bytes whose `pHYs` chunk says `dpi` (so a viewer prints it at its size).
pub fn png_bytes(img: &GrayImage, dpi: u32) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    img.write_with_encoder(image::codecs::png::PngEncoder::new(&mut bytes))
        .map_err(|e| anyhow!("board.png: {e}"))?;
    // after the signature (8 bytes) and IHDR (4 + 4 + 13 + 4)
    let at = 8 + 25;
    let ppm = (dpi as f64 / 0.0254).round() as u32;
    let mut chunk = Vec::with_capacity(21);
    chunk.extend_from_slice(&9u32.to_be_bytes());
    let mut body = b"pHYs".to_vec();
    body.extend_from_slice(&ppm.to_be_bytes());
    body.extend_from_slice(&ppm.to_be_bytes());
    body.push(1); // unit: metre
    chunk.extend_from_slice(&body);
    chunk.extend_from_slice(&crc32(&body).to_be_bytes());
    bytes.splice(at..at, chunk);
    Ok(bytes)
}

/// `img` as a one-page PDF whose page is the picture at `dpi` exactly (its size in points =
/// pixels / dpi x 72), so that printing at "actual size" gives the board's scale: one grey image
/// XObject, Flate-compressed, drawn over the whole page.
pub fn pdf_bytes(img: &GrayImage, dpi: u32) -> Vec<u8> {
    use pdf_writer::{Content, Filter, Finish, Name, Pdf, Rect, Ref};
    let (w, h) = (img.width(), img.height());
    let points = |px: u32| px as f32 / dpi as f32 * 72.0;
    let (wp, hp) = (points(w), points(h));
    let (catalog, tree, page_id, image_id, content_id) =
        (Ref::new(1), Ref::new(2), Ref::new(3), Ref::new(4), Ref::new(5));
    let name = Name(b"Board");
    let mut pdf = Pdf::new();
    pdf.catalog(catalog).pages(tree);
    pdf.pages(tree).kids([page_id]).count(1);
    let mut page = pdf.page(page_id);
    page.media_box(Rect::new(0.0, 0.0, wp, hp));
    page.parent(tree);
    page.contents(content_id);
    page.resources().x_objects().pair(name, image_id);
    page.finish();
    let data = miniz_oxide::deflate::compress_to_vec_zlib(img.as_raw(), 6);
    let mut image = pdf.image_xobject(image_id, &data);
    image.filter(Filter::FlateDecode);
    image.width(w as i32);
    image.height(h as i32);
    image.color_space().device_gray();
    image.bits_per_component(8);
    image.finish();
    let mut content = Content::new();
    content.save_state();
    content.transform([wp, 0.0, 0.0, hp, 0.0, 0.0]);
    content.x_object(name);
    content.restore_state();
    pdf.stream(content_id, &content.finish());
    pdf.finish()
}

/// CRC-32 (ISO 3309, as PNG chunks use).
fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}
