use nav::fir::Fir;
use nav::coning::*;
fn main() {
    let fir = Fir::default_dither_filter();
    println!("{:?}", fir.response());
    for n in 2..=5 {
        let t = ConingCoefficients::taylor(n, &fir);
        let f = ConingCoefficients::fitted(n, &fir, 100.0);
        println!("n={n} classical {:?}\n  taylor {:?}\n  fitted {:?}\n  paper {:?}", classical(n).k, t.k, f.k, paper_000_tuned(n));
    }
    let n = 4;
    let c = classical(n);
    let t = ConingCoefficients::taylor(n, &fir);
    let f = ConingCoefficients::fitted(n, &fir, 100.0);
    let a = 1f64.to_radians();
    let d = |cc: &ConingCoefficients, fl: Option<&Fir>, hz: f64| cc.predicted_drift(fl, a, hz, 2000.0).to_degrees() * 60.0;
    for hz in [1.0, 10.0, 50.0, 80.0] {
        println!("{hz:5} alg1 {:10.3e} alg2 {:10.3e} alg3 {:10.3e} ours {:10.3e}", d(&c, None, hz), d(&c, Some(&fir), hz), d(&t, Some(&fir), hz), d(&f, Some(&fir), hz));
    }
    let mut worse = 0;
    for i in 1..=200 {
        let hz = i as f64 * 0.5;
        let (a2, o) = (d(&c, Some(&fir), hz).abs(), d(&f, Some(&fir), hz).abs());
        if o > a2 { worse += 1; println!("worse at {hz}: {o:e} vs {a2:e}"); }
    }
    println!("worse {worse}");
}
