//! A scenario's variants: the same scenario with other seeds (a Monte Carlo run, a campaign's
//! repeat) or with other navigation settings (a campaign's device), each still one scenario
//! that the bench, its in-process twin and the judge all read alike.

use super::Scenario;
use anyhow::{Context, Result, bail};

/// The tables of a scenario that are nav's own config tables, as nav's config file has them:
/// what a variant may override.
pub const NAV_TABLES: [&str; 5] = [
    "navigation",
    "north_finding",
    "self_calibration",
    "tetra_calibration",
    "processing",
];

/// `over` merged into `base`: tables key by key, all else replaced.
fn merge(base: &mut toml::Table, over: &toml::Table) {
    for (k, v) in over {
        match (base.get_mut(k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

impl Scenario {
    /// Run `run` of this scenario: the IMU, the mechanism and the receiver with other seeds
    /// (run 0 is the scenario itself).
    pub fn reseeded(&self, run: u64) -> Scenario {
        let mut s = self.clone();
        s.imu.seed = self.imu.seed + 1000 * run;
        if let Some(t) = s.turntable.as_mut() {
            t.seed += run;
        }
        if let Some(g) = s.gps.as_mut() {
            g.errors.seed += 1000 * run;
        }
        s
    }

    /// This scenario with nav's settings changed by `over`: tables and keys of nav's config
    /// file ([`NAV_TABLES`]), merged into the scenario's own (e.g. `[navigation.filter]
    /// gps_sigma_m = 0.5`). A table the scenario does not have is left out: the settings change
    /// how nav does what the scenario asks, not what it asks (a drill does not navigate
    /// because a device's navigation settings are given). The result is checked as any
    /// scenario is.
    pub fn with_nav_settings(&self, over: &toml::Table) -> Result<Scenario> {
        if let Some(k) = over.keys().find(|k| !NAV_TABLES.contains(&k.as_str())) {
            bail!(
                "nav settings: [{k}] is not one of nav's tables a scenario carries ({})",
                NAV_TABLES.join(", ")
            );
        }
        let mut table = toml::Table::try_from(self).context("the scenario as TOML")?;
        let present: toml::Table = over
            .iter()
            .filter(|(k, _)| table.contains_key(*k))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        merge(&mut table, &present);
        let s: Scenario = table
            .try_into()
            .context("nav settings merged into the scenario")?;
        s.check().context("nav settings merged into the scenario")?;
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drive() -> Scenario {
        Scenario::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/drive-gps.toml"),
        )
        .expect("shipped scenario")
    }

    #[test]
    fn a_variant_changes_only_what_it_names() {
        let s = drive();
        assert_eq!(s.reseeded(0), s);
        let r = s.reseeded(3);
        assert_eq!(r.imu.seed, s.imu.seed + 3000);
        let (g, g0) = (r.gps.as_ref().expect("gps"), s.gps.as_ref().expect("gps"));
        assert_eq!(g.errors.seed, g0.errors.seed + 3000);
        assert_eq!(r.drive, s.drive);
        let over: toml::Table =
            toml::from_str("[navigation.filter]\ngps_sigma_m = 0.5\n").expect("parses");
        let v = s.with_nav_settings(&over).expect("merged");
        let f = &v.navigation.as_ref().expect("navigation").filter;
        assert_eq!(f.gps_sigma_m, 0.5);
        // the rest of the filter, and of the scenario, as it was
        let f0 = &s.navigation.as_ref().expect("navigation").filter;
        assert_eq!(f.gps_gm_sigma_m, f0.gps_gm_sigma_m);
        assert_eq!(
            Scenario {
                navigation: s.navigation.clone(),
                ..v.clone()
            },
            s
        );
        // a drive does not find north because north-finding settings are given
        let nf: toml::Table = toml::from_str("[north_finding]\ndwell_s = 10.0\n").expect("parses");
        assert_eq!(s.with_nav_settings(&nf).expect("merged"), s);
    }

    #[test]
    fn bad_nav_settings_say_what_is_wrong() {
        let s = drive();
        let bad = |text: &str, want: &str| {
            let over: toml::Table = toml::from_str(text).expect("parses");
            let e = s.with_nav_settings(&over).expect_err(want);
            assert!(format!("{e:#}").contains(want), "{e:#} (expected {want})");
        };
        bad("[gps]\nrate_hz = 5.0\n", "[gps] is not one of nav's tables");
        bad(
            "[navigation.filter]\ngps_sigma = 0.5\n",
            "unknown field `gps_sigma`",
        );
    }
}
