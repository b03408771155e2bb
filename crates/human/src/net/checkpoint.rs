//! Network weights on disk, with the configuration that shaped them stored beside them, so that
//! weights of another preset, variant or width are refused with a one-line error instead of
//! failing on the first mismatched tensor (or, worse, loading where the shapes happen to match).
//!
//! The file is sealed ([`fewview_scene::sealed`]: magic, payload, CRC-32, written atomically);
//! the payload is the configuration's JSON length (u32, little-endian), the JSON, and Burn's
//! own record of the module (burnpack, [`burn::store::ModuleRecord`]).

use std::path::Path;

use burn::module::Module;
use burn::store::ModuleRecord;
use burn::tensor::{Bytes, Device};
use fewview_scene::sealed;

use super::config::NetConfig;
use super::model::PoseGaussianNet;
use crate::error::{HumanError, Result};

const MAGIC: &[u8] = b"FVHNET1\0";
const WHAT: &str = "a PoseGaussian network checkpoint";

/// Writes `net`'s weights and configuration to `path` (atomically).
pub fn save(net: &PoseGaussianNet, path: &Path) -> Result<()> {
    let json = serde_json::to_vec(net.config()).expect("a config serialises");
    let record = net.clone().into_record();
    let weights = record
        .into_bytes()
        .map_err(|e| HumanError::format(path, format!("cannot encode the weights: {e}")))?;
    let mut payload = Vec::with_capacity(4 + json.len() + weights.len());
    payload.extend_from_slice(&(json.len() as u32).to_le_bytes());
    payload.extend_from_slice(&json);
    payload.extend_from_slice(&weights);
    Ok(sealed::write(path, MAGIC, &payload)?)
}

/// The configuration stored in the checkpoint at `path`, without its weights.
pub fn stored_config(path: &Path) -> Result<NetConfig> {
    Ok(split(path, &sealed::read(path, MAGIC, &[], WHAT)?)?.0)
}

/// A network of configuration `expected` with the weights at `path` on `device`; an error if the
/// file holds the weights of any other configuration.
pub fn load(path: &Path, expected: &NetConfig, device: &Device) -> Result<PoseGaussianNet> {
    let payload = sealed::read(path, MAGIC, &[], WHAT)?;
    let (stored, weights) = split(path, &payload)?;
    if &stored != expected {
        return Err(HumanError::invalid(
            path,
            format!("weights of another network ({stored}), expected {expected}"),
        ));
    }
    let record = ModuleRecord::from_bytes(Bytes::from_bytes_vec(weights.to_vec()))
        .map_err(|e| HumanError::format(path, format!("unreadable weights: {e}")))?;
    PoseGaussianNet::new(expected, device)?
        .try_load_record(record)
        .map_err(|e| HumanError::format(path, format!("weights do not fit the network: {e}")))
}

/// The stored configuration and the weights' bytes.
fn split<'a>(path: &Path, payload: &'a [u8]) -> Result<(NetConfig, &'a [u8])> {
    let corrupt = |m: &str| HumanError::format(path, format!("corrupt {WHAT}: {m}"));
    let len_bytes: [u8; 4] = payload
        .get(..4)
        .and_then(|b| b.try_into().ok())
        .ok_or_else(|| corrupt("no header"))?;
    let len = u32::from_le_bytes(len_bytes) as usize;
    let json = payload
        .get(4..4 + len)
        .ok_or_else(|| corrupt("truncated configuration"))?;
    let config: NetConfig =
        serde_json::from_slice(json).map_err(|e| corrupt(&format!("configuration: {e}")))?;
    Ok((config, &payload[4 + len..]))
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Distribution, Tensor};

    use super::*;
    use crate::net::seed::seeded;
    use crate::net::{NetInput, Variant};

    fn tiny() -> NetConfig {
        NetConfig {
            widths: [2, 3, 4, 5],
            pose_channels: 2,
            ..NetConfig::cpu(Variant::Normalized)
        }
    }

    fn input(device: &Device) -> NetInput {
        let r = |c: usize| Tensor::random([1, c, 8, 8], Distribution::Uniform(0.0, 1.0), device);
        NetInput {
            image: r(3),
            pose: r(2),
            depth: r(1),
        }
    }

    fn running_mean(net: &PoseGaussianNet) -> Vec<f32> {
        let bn = net.image.stages[0].units[0].norm1.as_ref().unwrap();
        bn.running_mean
            .value()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()
    }

    /// Weights and batch-norm statistics (moved off their initial values by one training-mode
    /// pass) come back exactly: the loaded network's outputs equal the saved one's.
    #[test]
    fn checkpoint_round_trip_gives_the_same_outputs() {
        let _rng = seeded(4);
        let train = Device::flex().autodiff();
        let config = tiny();
        let net = PoseGaussianNet::new(&config, &train).unwrap();
        net.forward(input(&train)).unwrap();
        let net = net.valid();
        assert!(running_mean(&net).iter().any(|&m| m != 0.0));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("net.fvh");
        save(&net, &path).unwrap();
        assert_eq!(stored_config(&path).unwrap(), config);
        let device = Device::flex();
        let loaded = load(&path, &config, &device).unwrap();
        assert_eq!(running_mean(&loaded), running_mean(&net));
        let x = input(&device);
        let a = net.forward(x.clone()).unwrap().scale.into_data();
        let b = loaded.forward(x).unwrap().scale.into_data();
        assert_eq!(
            a.try_to_vec::<f32>().unwrap(),
            b.try_to_vec::<f32>().unwrap()
        );
    }

    /// Weights of another preset or variant are refused before any tensor is read.
    #[test]
    fn checkpoint_refuses_another_configuration_in_one_line() {
        let device = Device::flex();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cpu.fvh");
        let cpu = NetConfig::cpu(Variant::Normalized);
        save(&PoseGaussianNet::new(&cpu, &device).unwrap(), &path).unwrap();
        let e = load(&path, &NetConfig::paper(Variant::Normalized), &device).unwrap_err();
        let e = e.to_string();
        assert!(!e.contains('\n'), "{e}");
        assert!(
            e.ends_with(
                "cpu.fvh: weights of another network (preset cpu, config 3, widths 16/32/48/64, \
                 33 pose channels, input 256×128, softplus β 100), expected preset paper, config 3, \
                 widths 32/64/96/128, 33 pose channels, input 512×512, softplus β 100"
            ),
            "{e}"
        );
        let e = load(&path, &NetConfig::cpu(Variant::DeepResidual), &device).unwrap_err();
        assert!(
            e.to_string().contains("expected preset cpu, config 2"),
            "{e}"
        );
        assert!(load(&path, &cpu, &device).is_ok());
    }
}
