#!/bin/sh
# The team's Zenoh identities (deploy/zenoh/README.md): a certificate authority made once per team, and one
# certificate per machine signed by it, its common name the identity the access control names (skyfix, operator,
# drone-a, drone-b, blueos). Run it on a machine kept off the field network; keep ca-key.pem there only.
#
#   deploy/make_certs.sh DIR NAME[=ADDRESS,...] ...
#   deploy/make_certs.sh ~/skyfix-team skyfix=192.168.2.1 blueos=192.168.2.2 operator drone-a=192.168.2.3
#
# DIR/ca.pem and DIR/ca-key.pem are made the first time and reused after (a new laptop: run it again with only its
# name). Each NAME gets DIR/NAME/ with ca.pem, skyfix-cert.pem and skyfix-key.pem (mode 0600), to copy to that
# machine's /etc/skyfix/tls/. ADDRESS: the IP addresses or host names others connect to it by (a machine that
# only connects needs none). An existing DIR/NAME is refused: remove it to make that identity anew.
set -eu
[ $# -ge 2 ] || { sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//'; exit 2; }
dir=$1; shift
umask 077
mkdir -p "$dir"
key="-newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes"
if [ ! -f "$dir/ca.pem" ]; then
    openssl req -x509 $key -keyout "$dir/ca-key.pem" -out "$dir/ca.pem" -days 3650 -subj "/CN=skyfix team CA" \
        -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" 2>/dev/null
    echo "made the team's CA: $dir/ca.pem (keep $dir/ca-key.pem off the field network)"
fi
for arg in "$@"; do
    name=${arg%%=*}
    case $name in ''|*[!A-Za-z0-9._-]*) echo "make_certs.sh: $arg: a name of letters, digits, . _ -" >&2; exit 2;; esac
    out="$dir/$name"
    [ ! -e "$out" ] || { echo "make_certs.sh: $out exists (remove it to make $name anew)" >&2; exit 2; }
    san="DNS:$name"
    if [ "$arg" != "$name" ]; then
        for a in $(echo "${arg#*=}" | tr ',' ' '); do
            case $a in *[!0-9.]*) san="$san,DNS:$a";; *) san="$san,IP:$a";; esac
        done
    fi
    mkdir "$out"
    printf 'subjectAltName=%s\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\n' \
        "$san" > "$out/ext"
    openssl req $key -keyout "$out/skyfix-key.pem" -out "$out/req.csr" -subj "/CN=$name" 2>/dev/null
    openssl x509 -req -in "$out/req.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca-key.pem" -CAcreateserial \
        -out "$out/skyfix-cert.pem" -days 825 -extfile "$out/ext" 2>/dev/null
    rm "$out/req.csr" "$out/ext"
    cp "$dir/ca.pem" "$out/ca.pem"
    chmod 600 "$out/skyfix-key.pem"
    chmod 644 "$out/skyfix-cert.pem" "$out/ca.pem"
    echo "$name: $out/ (subjectAltName $san)"
done
