use frf_data::FrfDataset;
fn main() {
    let dir = frf_data::shared_data::shared_data_dir().unwrap();
    let name = std::env::args().nth(1).unwrap_or("wafer_nominal".into());
    let data = frf_data::io::read_frf_csv(dir.join(format!("{name}.csv"))).unwrap();
    let clean = frf_data::io::read_frf_csv(dir.join("wafer_nominal.noiseless.csv")).unwrap();
    let n = data.n_lines();
    let m = data.n_entries();
    let mut t = vec![0.0; n];
    let mut tot = 0.0;
    for k in 0..n {
        for e in 0..m {
            let (i, j) = (e % 4, e / 4);
            let d = data.value(k, i, j) - clean.value(k, i, j);
            let v = data.variance(k, i, j).unwrap();
            t[k] += 2.0 * d.norm_sqr() / v;
        }
        tot += t[k];
    }
    println!("mean 2T/ (2m) = {}", tot / n as f64 / (2.0 * m as f64));
    // print lines with largest t
    let mut idx: Vec<usize> = (0..n).collect();
    idx.sort_by(|&a, &b| t[b].total_cmp(&t[a]));
    for &k in idx.iter().take(15) {
        println!("{:8.2} Hz  {:8.1}", data.freq_hz(k), t[k]);
    }
    let mut s = t.clone();
    s.sort_by(|a, b| a.total_cmp(b));
    println!(
        "median {} p99 {} max {}",
        s[n / 2],
        s[n * 99 / 100],
        s[n - 1]
    );
    for lo in [100.0, 140.0, 150.0, 160.0, 170.0, 200.0, 500.0, 1000.0] {
        let sel: Vec<f64> = (0..n)
            .filter(|&k| data.freq_hz(k) >= lo && data.freq_hz(k) < lo * 1.1)
            .map(|k| t[k])
            .collect();
        println!(
            "band {lo}..{}: mean {:.1}",
            lo * 1.1,
            sel.iter().sum::<f64>() / sel.len() as f64
        );
    }
}
