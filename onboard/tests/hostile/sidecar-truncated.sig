{
  "format": 1,
  "algorithm": "ed25519",
  "key_id": "3bda5612",
  "public_key": "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f",
  "name": "result.json",
  "kind": "json",
  "size": 2,
  "sha256": "0000000000000000000000000000000000000000000000000000000000000000",
  "parts": [
    [
      "/x0",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x1",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x2",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x3",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x4",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x5",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x6",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x7",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x8",
      "abababababababababababababababababababababababababababababababab"
    ],
    [
      "/x9",
      "abab