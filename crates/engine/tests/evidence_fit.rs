//! The fingerprint fit from map evidence (docs/evidence.md#what-it-holds): a scan of weight 1
//! at a state is one training sample there, so the censored EM on the evidence's moments is
//! the survey's fit of the same readings, and evidence merged twice is each sample twice.

use nalgebra::Point2;
use waymark_engine::evidence::{Evidence, TransmitterKey};
use waymark_engine::radio::{fit_censored_moments, CensoredFit, FitOptions, Gaussian, RssiModel};
use waymark_engine::site::{BuildOptions, SiteBuilder};
use waymark_engine::TransmitterId;

fn close(a: Gaussian, b: Gaussian) {
    assert!((a.mean_dbm - b.mean_dbm).abs() < 1e-6 && (a.std_db - b.std_db).abs() < 1e-6, "{a:?} {b:?}");
}

#[test]
fn the_weighted_fit_is_the_fit_of_the_samples_repeated() {
    let mut b = SiteBuilder::new("one");
    let f = b.floor("G", 0.0);
    b.state(f, Point2::new(0.0, 0.0), vec![]);
    let site = b.build(BuildOptions::default()).unwrap();
    let options = FitOptions { clip_dbm: site.radio().clip_dbm(), max_std_db: 8.0, ..FitOptions::default() };
    let key = TransmitterKey::of(&TransmitterId::wifi("02:00:00:00:00:01").unwrap());
    let mut e = Evidence::new(&site);
    let mut samples = Vec::new();
    for (i, r) in [-61.0, -64.0, -70.0, -58.0, -66.0].into_iter().enumerate() {
        e.add_scan(&[(0, 1.0)], &[(key, r)], [true, false]).unwrap();
        samples.push(r);
        // Every other scan misses the transmitter: a clipped sample.
        if i % 2 == 0 {
            e.add_scan(&[(0, 1.0)], &[], [true, false]).unwrap();
            samples.push(options.clip_dbm);
        }
    }
    let fit: CensoredFit = fit_censored_moments(&e.moments(0, &key).unwrap(), &options);
    assert!(fit.converged);
    close(fit.gaussian.unwrap(), RssiModel::CensoredGaussian.fit(&samples, &options).unwrap());
    let mut twice = e.clone();
    twice.merge(&e).unwrap();
    let doubled: Vec<f64> = samples.iter().chain(&samples).copied().collect();
    let fit = fit_censored_moments(&twice.moments(0, &key).unwrap(), &options);
    close(fit.gaussian.unwrap(), RssiModel::CensoredGaussian.fit(&doubled, &options).unwrap());
    // Half a scan's weight at each of two states is half a sample at each.
    let mut b = SiteBuilder::new("two");
    let f = b.floor("G", 0.0);
    b.state(f, Point2::new(0.0, 0.0), vec![]);
    b.state(f, Point2::new(1.0, 0.0), vec![]);
    let two = b.build(BuildOptions::default()).unwrap();
    let mut halves = Evidence::new(&two);
    for r in [-61.0, -64.0] {
        halves.add_scan(&[(0, 0.5), (1, 0.5)], &[(key, r)], [true, false]).unwrap();
    }
    let m = halves.moments(1, &key).unwrap();
    assert_eq!((m.samples, m.heard, m.heard_mean), (1.0, 1.0, -62.5));
}
