//! Tests of the table reader.

use super::*;

fn spec(n: usize) -> TableSpec {
    TableSpec {
        time: Some((0, TimeUnit::S)),
        values: (1..=n).collect(),
        names: (1..=n).map(|i| format!("v{i}")).collect(),
        ..Default::default()
    }
}

#[test]
fn parses_csv_whitespace_headers_and_comments() {
    let p = Path::new("x.csv");
    let t = parse_table_from(p, "#c\ntime,a,b\n0.0,1,2\n0.5, 3 ,4\n".as_bytes(), &spec(2)).unwrap();
    assert_eq!(t.t_ns, vec![0, 500_000_000]);
    assert_eq!(t.columns, vec![vec![1.0, 3.0], vec![2.0, 4.0]]);
    assert_eq!((t.lines.line(0), t.lines.line(1)), (3, 4));
    assert_eq!(t.header.as_deref(), Some("time,a,b"));
    let t = parse_table_from(p, "  1 2 3\n\n2\t4 5\n".as_bytes(), &spec(2)).unwrap();
    assert_eq!(t.columns[1], vec![3.0, 5.0]);
    assert_eq!((t.lines.line(0), t.lines.line(1)), (1, 3));
}

#[test]
fn folders_utf16_and_binary_files_are_named() {
    let dir = std::env::temp_dir().join(format!("tumble-table-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let e = read_table(&dir, &spec(3)).unwrap_err().to_string();
    assert!(e.contains("is a folder"), "{e}");
    let utf16: Vec<u8> = [0xFF, 0xFE].into_iter().chain("1,2,3,4\n".bytes().flat_map(|b| [b, 0])).collect();
    let p = dir.join("utf16.csv");
    std::fs::write(&p, utf16).unwrap();
    let e = read_table(&p, &spec(3)).unwrap_err().to_string();
    assert!(e.contains("UTF-16") && !e.contains('\0'), "{e}");
    std::fs::write(&p, [1u8, 0, 7, 200, 0, 3, 0, 0, 9, b'\n']).unwrap();
    let e = read_table(&p, &spec(3)).unwrap_err().to_string();
    assert!(e.contains("binary") || e.contains("UTF-16"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn errors_name_line() {
    let p = Path::new("x.csv");
    let e = parse_table_from(p, "0,1,2\n1,nan,2\n".as_bytes(), &spec(2)).unwrap_err().to_string();
    assert!(e.contains("x.csv:2:") && e.contains("not finite"), "{e}");
    let e = parse_table_from(p, "0,1,2\n1,2\n".as_bytes(), &spec(2)).unwrap_err().to_string();
    assert!(e.contains("x.csv:2:") && e.contains("truncated"), "{e}");
    let e = parse_table_from(p, "".as_bytes(), &spec(2)).unwrap_err().to_string();
    assert!(e.contains("no data rows"), "{e}");
    let e = parse_table_from(p, "0,1,2\n1,x,2\n".as_bytes(), &spec(2)).unwrap_err().to_string();
    assert!(e.contains("'x' is not a number"), "{e}");
}

#[test]
fn large_input_is_split_and_numbered_right() {
    let mut s = String::new();
    for i in 0..200_000 {
        s.push_str(&format!("{i},{}.5,{}\n", i, 2 * i));
    }
    s.push_str("200000,1,oops\n");
    let e = parse_table_from(Path::new("big.csv"), s.as_bytes(), &spec(2)).unwrap_err().to_string();
    assert!(e.contains("big.csv:200001:"), "{e}");
    s.truncate(s.len() - "200000,1,oops\n".len());
    let t = parse_table_from(Path::new("big.csv"), s.as_bytes(), &spec(2)).unwrap();
    assert_eq!(t.t_ns.len(), 200_000);
    assert_eq!(t.lines.line(199_999), 200_000);
    assert_eq!(t.columns[0][123_456], 123_456.5);
}

#[test]
fn odd_but_valid_lines_parse_like_the_general_path() {
    let text = "# c\r\n1, 2.5 ,-3e-2,9\r\n\n  2,\t+4,5.000000000001,x\n# mid\n3,1e3,-0.5\n4,12345678901234567890,0.1";
    let t = parse_table_from(Path::new("odd.csv"), text.as_bytes(), &spec(2)).unwrap();
    assert_eq!(t.t_ns, vec![1_000_000_000, 2_000_000_000, 3_000_000_000, 4_000_000_000]);
    assert_eq!(t.columns[0], vec![2.5, 4.0, 1e3, 12345678901234567890.0]);
    assert_eq!(t.columns[1], vec![-3e-2, 5.000000000001, -0.5, 0.1]);
    assert_eq!((0..4).map(|i| t.lines.line(i)).collect::<Vec<_>>(), vec![2, 4, 6, 7]);
    let e = parse_table_from(Path::new("big.csv"), "1,1e999,2\n".as_bytes(), &spec(2)).unwrap_err().to_string();
    assert!(e.contains("big.csv:1:") && e.contains("not finite"), "{e}");
    let ws = "1 2 3\n 2\t4   5 extra\n";
    let t = parse_table_from(Path::new("ws.txt"), ws.as_bytes(), &spec(2)).unwrap();
    assert_eq!(t.columns[1], vec![3.0, 5.0]);
}

#[test]
fn eight_digit_swar_matches_plain_parsing() {
    assert_eq!(eight_digits(b"12345678", 0), Some(12_345_678));
    assert_eq!(eight_digits(b"x00000001", 1), Some(1));
    assert_eq!(eight_digits(b"1234567", 0), None);
    assert_eq!(eight_digits(b"1234a678", 0), None);
    assert_eq!(eight_digits(b"1234/678", 0), None);
    assert_eq!(eight_digits(b"1234:678", 0), None);
    for text in ["0.024501082", "-9.538499414", "123.4567890123", "1e-3", "0.000000001234567890", "7"] {
        let (v, end) = parse_number(text.as_bytes(), 0).unwrap();
        assert_eq!(end, text.len());
        assert_eq!(v, text.parse::<f64>().unwrap(), "{text}");
    }
}

#[test]
fn nanosecond_stamps_keep_all_digits() {
    let sp =
        TableSpec { time: Some((0, TimeUnit::Ns)), values: vec![1], names: vec!["a".into()], ..Default::default() };
    let t = parse_table_from(Path::new("x"), "1403715273262142976,1\n".as_bytes(), &sp).unwrap();
    assert_eq!(t.t_ns[0], 1403715273262142976);
}
