//! The training images as the loop holds them: the target on the compute device, with the
//! photo's alpha (to composite it over another background) and the mask of its valid pixels.

use burn::tensor::{Device, Tensor, TensorData};

use crate::raster::RenderCamera;

/// A training image as the loop uses it.
#[derive(Clone, Debug)]
pub struct TrainView {
    pub name: String,
    pub camera: RenderCamera,
    /// `[H, W, 3]` target.
    pub target: Tensor<3>,
    /// The image's alpha, when it has one: lets the loop composite it over other backgrounds.
    pub(super) alpha: Option<AlphaTensors>,
    /// `[H, W, 1]`, 1 where the image holds photo data and 0 in the blank border of an
    /// undistorted photo; the photometric loss sees neither render nor target there.
    pub valid: Option<Tensor<3>>,
}

/// An RGBA photograph stored composited over a known background, so that it can be
/// re-composited over any colour: `rgb·a + (1 − a)·new = image + (1 − a)·(new − old)`.
#[derive(Clone, Debug)]
pub struct AlphaImage {
    /// The composited image, `[H, W, 3]` row-major.
    composited: Vec<f32>,
    /// Alpha, `[H, W]`.
    alpha: Vec<f32>,
    /// The colour `composited` was composited over.
    background: [f32; 3],
    height: usize,
    width: usize,
}

impl AlphaImage {
    /// `image` (3 channels) composited over `background` with alpha `alpha` (1 channel, same
    /// size); `None` when the shapes disagree.
    pub fn new(
        image: &fewview_scene::Image,
        alpha: &fewview_scene::Image,
        background: [f32; 3],
    ) -> Option<Self> {
        let same = image.width == alpha.width && image.height == alpha.height;
        (same && image.channels == 3 && alpha.channels == 1).then(|| Self {
            composited: image.data.clone(),
            alpha: alpha.data.clone(),
            background,
            height: image.height,
            width: image.width,
        })
    }

    /// The image and `1 − alpha` on `device`.
    fn upload(&self, device: &Device) -> AlphaTensors {
        let (h, w) = (self.height, self.width);
        let one_minus: Vec<f32> = self.alpha.iter().map(|a| 1.0 - a).collect();
        AlphaTensors {
            composited: Tensor::<3>::from_data(
                TensorData::new(self.composited.clone(), [h, w, 3]),
                device,
            ),
            one_minus_alpha: Tensor::<3>::from_data(TensorData::new(one_minus, [h, w, 1]), device),
            background: self.background,
        }
    }
}

/// An [`AlphaImage`] on the compute device, so that compositing it over an iteration's
/// background is a tensor operation and uploads nothing but the colour.
#[derive(Clone, Debug)]
pub(super) struct AlphaTensors {
    /// `[H, W, 3]`
    composited: Tensor<3>,
    /// `[H, W, 1]`
    one_minus_alpha: Tensor<3>,
    background: [f32; 3],
}

impl AlphaTensors {
    /// `image + (1 − a)·(new − old)`.
    pub(super) fn over(&self, background: [f32; 3]) -> Tensor<3> {
        let shift = [0, 1, 2].map(|c| background[c] - self.background[c]);
        let device = self.composited.device();
        let shift = Tensor::<3>::from_data(TensorData::new(shift.to_vec(), [1, 1, 3]), &device);
        self.composited.clone() + self.one_minus_alpha.clone() * shift
    }
}

impl TrainView {
    pub fn new(
        name: impl Into<String>,
        camera: RenderCamera,
        image: &fewview_scene::Image,
        device: &Device,
    ) -> Self {
        let target = Tensor::<3>::from_data(
            TensorData::new(
                image.data.clone(),
                [image.height, image.width, image.channels],
            ),
            device,
        );
        Self {
            name: name.into(),
            camera,
            target,
            alpha: None,
            valid: None,
        }
    }

    /// Attaches a validity mask (1 channel, the image's size; see [`TrainView::valid`]).
    /// A mask of another shape is ignored.
    pub fn with_valid(mut self, valid: &fewview_scene::Image, device: &Device) -> Self {
        let [h, w, _] = self.target.dims();
        if valid.channels == 1 && valid.width == w && valid.height == h {
            let data = TensorData::new(valid.data.clone(), [h, w, 1]);
            self.valid = Some(Tensor::<3>::from_data(data, device));
        }
        self
    }

    /// Attaches the image's alpha (see [`AlphaImage`]).
    pub fn with_alpha(mut self, alpha: AlphaImage) -> Self {
        self.alpha = Some(alpha.upload(&self.target.device()));
        self
    }

    /// The target composited over `background`, when the image has alpha.
    pub fn target_over(&self, background: [f32; 3]) -> Option<Tensor<3>> {
        self.alpha.as_ref().map(|a| a.over(background))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alpha_image_recomposites_over_a_new_background() {
        // rgb, alpha and the old background per pixel; composite by the definition.
        let rgb = [[0.2f32, 0.4, 0.6], [0.9, 0.1, 0.5], [0.3, 0.3, 0.3]];
        let a = [1.0f32, 0.25, 0.0];
        let (old, new) = ([1.0f32, 1.0, 1.0], [0.1f32, 0.7, 0.3]);
        let over = |bg: [f32; 3]| -> Vec<f32> {
            (0..3)
                .flat_map(|p| (0..3).map(move |c| rgb[p][c] * a[p] + (1.0 - a[p]) * bg[c]))
                .collect()
        };
        let image = fewview_scene::Image::from_vec(3, 1, 3, over(old));
        let alpha = fewview_scene::Image::from_vec(3, 1, 1, a.to_vec());
        let device = Device::flex();
        // The camera plays no part in compositing.
        let view = TrainView::new("v", crate::raster::tests::camera(), &image, &device)
            .with_alpha(AlphaImage::new(&image, &alpha, old).unwrap());
        let got: Vec<f32> = view
            .target_over(new)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        for (g, e) in got.iter().zip(over(new)) {
            assert!((g - e).abs() < 1e-6, "{got:?}");
        }
        assert!(AlphaImage::new(&image, &image, old).is_none());
    }
}
