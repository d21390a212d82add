#!/usr/bin/env bash
# Checks that the Waymark library makes no network calls, three ways:
#   1. its source (the SDK library's src/ and the engine's crates/engine/src/) names no
#      networking API (std::net, sockets);
#   2. the library's dependency tree, as shipped (no features, every target, Android too),
#      holds no networking crate;
#   3. the shared library imports no socket or name-resolution function from libc
#      (nm -D --undefined-only): code that is not linked in cannot be called.
# Usage: bash scripts/check-no-network.sh [libwaymark.so ...]
#        With no argument, builds and checks the release library ($CARGO_TARGET_DIR/release).
# What check 3 cannot see: system calls made without libc. The one dependency that makes them,
# rustix (through uniffi -> tempfile), has socket code only with its `net` feature, which check 2
# requires to be off.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
cd "$repo"
target=${CARGO_TARGET_DIR:-$repo/target}
status=0

echo "-- 1. no networking API in src/ and crates/engine/src/"
if grep -rnE 'std::net\b|\bTcpStream\b|\bTcpListener\b|\bUdpSocket\b|\bToSocketAddrs\b|\bUnix(Stream|Listener|Datagram)\b' src/ crates/engine/src/; then
    echo "check-no-network: the source above names a networking API" >&2
    status=1
fi

echo "-- 2. no networking crate among the library's dependencies"
deps=$(cargo tree --locked -e normal --target all --prefix none --format '{p}' -p waymark | awk '{print $1}' | sort -u)
network_crates='^(reqwest|hyper|hyper-util|h2|h3|quinn|ureq|curl|curl-sys|isahc|surf|attohttpc|minreq|ehttp|tokio|async-std|smol|mio|socket2|polling|tungstenite|tokio-tungstenite|native-tls|openssl|openssl-sys|rustls|tokio-rustls|webpki|trust-dns-resolver|hickory-resolver|url|http|reqwest-middleware|libp2p|zmq|nng|lettre|ssh2|libssh2-sys|mqtt|rumqttc|paho-mqtt|grpcio|tonic|sentry|opentelemetry)$'
if found=$(grep -E "$network_crates" <<<"$deps"); then
    echo "check-no-network: networking crates in the library's dependency tree: $found" >&2
    status=1
fi
echo "   $(wc -l <<<"$deps") crates, none of them networking"
# rustix (uniffi -> tempfile) makes system calls itself, invisible to check 3: its sockets
# exist only with its `net` feature.
if cargo tree --locked -e features -i rustix --target all 2>/dev/null | grep -q 'rustix feature "net"'; then
    echo "check-no-network: rustix is built with its \"net\" feature (raw socket syscalls)" >&2
    status=1
fi

echo "-- 3. no socket or resolver function imported by the shared library"
libs=("$@")
if [ ${#libs[@]} -eq 0 ]; then
    cargo build --locked --release -p waymark --lib --quiet
    libs=("$target/release/libwaymark.so")
fi
network_symbols='^(socket|socketpair|connect|bind|listen|accept|accept4|send|sendto|sendmsg|sendmmsg|recv|recvfrom|recvmsg|recvmmsg|shutdown|setsockopt|getsockopt|getpeername|getsockname|getaddrinfo|getnameinfo|freeaddrinfo|gethostbyname|gethostbyname2|gethostbyname_r|gethostbyaddr|res_init|res_query|res_search|__res_init|inet_pton|inet_aton|curl_.*|SSL_.*)$'
for lib in "${libs[@]}"; do
    imports=$(nm -D --undefined-only "$lib" | awk '{print $NF}' | sed 's/@.*//' | sort -u)
    if found=$(grep -E "$network_symbols" <<<"$imports"); then
        echo "check-no-network: $lib imports $(tr '\n' ' ' <<<"$found")" >&2
        status=1
    else
        echo "   $lib: $(wc -l <<<"$imports") imports, no networking function"
    fi
done
if [ "$status" = 0 ]; then
    echo "no network: 3 checks passed"
fi
exit "$status"
