#!/usr/bin/env bash
# Create a ROS 2 security keystore (the sros2 layout that rcl reads) with the openssl CLI only.
#
#   keystore.sh init    KEYSTORE [DOMAIN_ID]          CAs + signed governance (domain default 0)
#   keystore.sh enclave KEYSTORE NAME PUBLISH SUBSCRIBE
#                                                     identity + signed permissions of one enclave;
#                                                     PUBLISH/SUBSCRIBE: comma-separated ROS topics
#                                                     or "-" (none)
#   keystore.sh profile KEYSTORE [DOMAIN_ID] [FILE]   init + every enclave of FILE
#                                                     (default security/enclaves.txt)
#
# Layout (what rcl/rmw look up under KEYSTORE/enclaves/<enclave>):
#   public/{identity_ca,permissions_ca}.cert.pem   private/{identity_ca,permissions_ca}.key.pem
#   enclaves/governance.{xml,p7s}
#   enclaves/<enclave>/{cert.pem,key.pem,identity_ca.cert.pem,permissions_ca.cert.pem,
#                       governance.p7s,permissions.xml,permissions.p7s}
# Two separate CAs (identity, permissions), so one leaked CA key cannot both mint an identity and
# grant it rights. Keys are ECDSA P-256, signatures SHA-256 (what builtin.PKI-DH accepts).
# Documents are S/MIME signed in text mode (`smime -sign -text`): the DDS Security plugins verify
# them with the permissions CA (OMG DDS Security 1.1, 9.4.1.2.1 / 9.4.1.3.1).
# Environment: KEYSTORE_DAYS (validity of certificates and permissions, default 365).
set -euo pipefail
umask 077  # private keys readable by the owner only

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
DAYS="${KEYSTORE_DAYS:-365}"

die() { echo "keystore.sh: $*" >&2; exit 2; }

[[ "$DAYS" =~ ^[1-9][0-9]{0,4}$ ]] || die "KEYSTORE_DAYS must be a positive integer, got '$DAYS'"
command -v openssl >/dev/null || die "openssl not found"

check_domain() {
  [[ "$1" =~ ^[0-9]{1,3}$ ]] && (( $1 <= 232 )) || die "domain id must be 0..232, got '$1'"
}

# ROS topic name -> DDS topic name (rmw_fastrtps: "rt" prefix + absolute name).
dds_topic() {
  local t="$1"
  [[ "$t" =~ ^/?[A-Za-z_~][A-Za-z0-9_/]*$ ]] || die "not a ROS topic name: '$t'"
  [[ "$t" == /* ]] || t="/$t"
  echo "rt$t"
}

# One <topic> element per DDS topic.
topic_elements() {
  local -a topics
  IFS=',' read -ra topics <<< "$1"
  printf '            <topic>%s</topic>\n' "${topics[@]}"
}

new_ca() {  # new_ca KEYSTORE NAME COMMON_NAME
  local ks="$1" name="$2" cn="$3"
  openssl ecparam -name prime256v1 -genkey -noout -out "$ks/private/$name.key.pem" 2>/dev/null
  openssl req -x509 -new -sha256 -days "$DAYS" -key "$ks/private/$name.key.pem" \
    -subj "/CN=$cn" -addext "basicConstraints=critical,CA:TRUE" \
    -addext "keyUsage=critical,keyCertSign,cRLSign,digitalSignature" \
    -out "$ks/public/$name.cert.pem"
}

sign() {  # sign KEYSTORE IN OUT: S/MIME text signature by the permissions CA
  openssl smime -sign -text -md sha256 -in "$2" -out "$3" \
    -signer "$1/public/permissions_ca.cert.pem" -inkey "$1/private/permissions_ca.key.pem"
}

cmd_init() {
  local ks="$1" domain="${2:-0}"
  check_domain "$domain"
  [[ -e "$ks/public" ]] && die "$ks already holds a keystore"
  mkdir -p "$ks/public" "$ks/private" "$ks/enclaves"
  new_ca "$ks" identity_ca "ins_gnss_ros identity CA"
  new_ca "$ks" permissions_ca "ins_gnss_ros permissions CA"
  echo "$domain" > "$ks/domain_id"
  sed "s/@DOMAIN_ID@/$domain/" "$HERE/templates/governance.xml" > "$ks/enclaves/governance.xml"
  sign "$ks" "$ks/enclaves/governance.xml" "$ks/enclaves/governance.p7s"
  chmod 644 "$ks"/public/*.pem "$ks"/enclaves/governance.*
}

cmd_enclave() {
  local ks="$1" name="$2" publish="$3" subscribe="$4"
  [[ -f "$ks/domain_id" ]] || die "$ks is not a keystore (run: keystore.sh init $ks)"
  [[ "$name" =~ ^(/[A-Za-z_][A-Za-z0-9_]*)+$ ]] || die "enclave name must look like /a/b, got '$name'"
  local domain dir base pub="" sub="" t
  domain="$(cat "$ks/domain_id")"
  dir="$ks/enclaves${name}"
  base="${name##*/}"
  [[ -e "$dir/key.pem" ]] && die "enclave $name exists"
  mkdir -p "$dir"
  # Every node: its graph information, its log, parameter events and its own parameter services
  # (rq/<node>/..Request in, rr/<node>/..Reply out; the node is named after the enclave's leaf).
  local common="ros_discovery_info,rt/rosout,rt/parameter_events,rq/$base/*,rr/$base/*"
  local -a names
  if [[ "$publish" != "-" ]]; then
    IFS=',' read -ra names <<< "$publish"
    for t in "${names[@]}"; do pub+="$(dds_topic "$t"),"; done
  fi
  if [[ "$subscribe" != "-" ]]; then
    IFS=',' read -ra names <<< "$subscribe"
    for t in "${names[@]}"; do sub+="$(dds_topic "$t"),"; done
  fi
  # Identity: key and certificate with CN = enclave name, issued by the identity CA. The subject
  # is given through a config file because a CN starting with '/' confuses -subj parsing.
  local cnf="$dir/.req.cnf"
  printf '[req]\nprompt=no\ndistinguished_name=dn\n[dn]\nCN=%s\n' "$name" > "$cnf"
  openssl ecparam -name prime256v1 -genkey -noout -out "$dir/key.pem" 2>/dev/null
  openssl req -new -sha256 -key "$dir/key.pem" -config "$cnf" -out "$dir/req.csr"
  printf 'basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n' \
    > "$dir/.ext.cnf"
  openssl x509 -req -sha256 -days "$DAYS" -in "$dir/req.csr" -CA "$ks/public/identity_ca.cert.pem" \
    -CAkey "$ks/private/identity_ca.key.pem" -CAcreateserial -CAserial "$ks/private/identity_ca.srl" \
    -extfile "$dir/.ext.cnf" -out "$dir/cert.pem" 2>/dev/null
  rm -f "$cnf" "$dir/.ext.cnf" "$dir/req.csr"
  cp "$ks/public/identity_ca.cert.pem" "$ks/public/permissions_ca.cert.pem" \
     "$ks/enclaves/governance.p7s" "$dir/"
  # Permissions, valid from now for DAYS days.
  local before after
  before="$(date -u +%Y-%m-%dT%H:%M:%S)"
  after="$(date -u -d "+$DAYS days" +%Y-%m-%dT%H:%M:%S)"
  local topics_pub topics_sub
  topics_pub="$(topic_elements "${common},${pub%,}")"
  topics_sub="$(topic_elements "${common},${sub%,}")"
  awk -v enclave="$name" -v domain="$domain" -v before="$before" -v after="$after" \
      -v pubs="$topics_pub" -v subs="$topics_sub" '
    { gsub(/@ENCLAVE@/, enclave); gsub(/@DOMAIN_ID@/, domain)
      gsub(/@NOT_BEFORE@/, before); gsub(/@NOT_AFTER@/, after) }
    /^@PUBLISH@$/ { print pubs; next }
    /^@SUBSCRIBE@$/ { print subs; next }
    { print }' "$HERE/templates/permissions.xml" > "$dir/permissions.xml"
  sign "$ks" "$dir/permissions.xml" "$dir/permissions.p7s"
  chmod 600 "$dir/key.pem"
}

cmd_profile() {
  local ks="$1" domain="${2:-0}" file="${3:-$HERE/enclaves.txt}"
  [[ -f "$file" ]] || die "no enclaves file $file"
  cmd_init "$ks" "$domain"
  local name pub sub extra
  while read -r name pub sub extra; do
    [[ -z "$name" || "$name" == \#* ]] && continue
    [[ -n "$sub" && -z "$extra" ]] || die "$file: expected 'enclave publish subscribe', got '$name $pub $sub $extra'"
    cmd_enclave "$ks" "$name" "$pub" "$sub"
  done < "$file"
}

usage() { sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }

case "${1:-}" in
  init)    (( $# >= 2 && $# <= 3 )) || usage; cmd_init "${@:2}" ;;
  enclave) (( $# == 5 )) || usage; cmd_enclave "${@:2}" ;;
  profile) (( $# >= 2 && $# <= 4 )) || usage; cmd_profile "${@:2}" ;;
  *) usage ;;
esac
