//! Every ONNX golden of the fixtures loads in tract and runs on inputs of the
//! declared shapes (a guard for the exporter: a graph tract cannot run would
//! silently drop out of the module tests otherwise).

use duolando_tests::{fixture, tensor_f32, tensor_i64, Onnx};

fn check_model(model: &str) -> usize {
    let dir = fixture(&format!("{model}/onnx"));
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("index.json")).unwrap()).unwrap();
    let mut n = 0;
    for entry in index.as_array().unwrap() {
        let file = entry["file"].as_str().unwrap();
        let onnx = Onnx::load(&dir.join(file));
        eprintln!("{model}/{file}: optimized={}", onnx.optimized);
        let inputs = entry["inputs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|i| {
                let shape: Vec<usize> = i["shape"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|d| d.as_u64().unwrap() as usize)
                    .collect();
                let numel: usize = shape.iter().product();
                match i["dtype"].as_str().unwrap() {
                    "float32" => tensor_f32(&shape, &vec![0.1f32; numel]),
                    "int64" => tensor_i64(&shape, &vec![1i64; numel]),
                    d => panic!("{file}: unexpected dtype {d}"),
                }
            })
            .collect();
        let outs = onnx.run(inputs);
        assert_eq!(
            outs.len(),
            entry["outputs"].as_array().unwrap().len(),
            "{file}: output count"
        );
        for (o, want) in outs.iter().zip(entry["outputs"].as_array().unwrap()) {
            let shape: Vec<usize> = want["shape"]
                .as_array()
                .unwrap()
                .iter()
                .map(|d| d.as_u64().unwrap() as usize)
                .collect();
            assert_eq!(o.shape(), &shape[..], "{file}: output shape");
        }
        n += 1;
    }
    n
}

#[test]
fn every_tiny_onnx_golden_runs_in_tract() {
    assert_eq!(check_model("tiny"), 30);
}

#[test]
fn every_tiny2_onnx_golden_runs_in_tract() {
    assert_eq!(check_model("tiny2"), 21);
}
