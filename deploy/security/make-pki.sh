#!/usr/bin/env bash
# Makes a DDS-Security PKI for bsn with openssl: one certificate authority, one identity per process, and the
# governance and permissions documents signed by that authority.
#
#   deploy/security/make-pki.sh [--submessages encrypt|sign|none] [--body FILE] OUT_DIR [NAME:ROLE[:NODES] ...]
#
# ROLE is one of
#   sensor       publishes bsn/raw for its NODES only (comma-separated node ids: NAME:sensor:thigh_l,shank_l for a
#                hub with two sensors), and bsn/truth/orientation, bsn/truth/segment_orientation and
#                bsn/truth/joint_angles, for simulators
#   fusion       reads raw, calibration results and status; publishes orientation, joint angles, status
#   calibration  reads raw and calibration requests; publishes calibration results and progress
#   viewer       reads orientation, joint angles, status (and the simulator's truth): bsn view
#   ros2-bridge  reads raw, orientation and joint angles; publishes the ROS 2 mirror (rt/tf, rt/bsn/...)
#   operator     a calibration client: publishes requests; reads progress, results and status
#   recorder     reads every bsn topic
#   tester       publishes raw samples of any node and reads every bsn topic (for tests and benchmarks, not a lab)
# --body FILE adds one sensor identity per node of that body model, named sensor-NODE, allowed that node only.
# Without NAME:ROLE arguments it makes one identity per role but sensor, named after the role, and the sensor
# identities of --body FILE (default: the default lower body of `bsn fusion --print-body`). Each identity gets a folder
# OUT_DIR/NAME holding what `bsn ... --security OUT_DIR/NAME` reads: ca.pem, cert.pem, key.pem, governance.p7s,
# permissions.p7s. OUT_DIR/ca holds the authority's key: keep it off the lab machines. Running the script again
# with new identities keeps the existing authority and re-signs the permissions for all of them.
#
# A sensor's node ids are DDS partitions in its permissions: Fast DDS refuses a writer of bsn/raw in any other
# partition (locally, and at every remote reader), and fusion takes a node's samples only from writers in the
# partition of that node. The permissions document travels in plaintext in the authentication handshake, so the node
# ids a sensor may write, like the topic names, are visible on the network (README: what discovery reveals).
#
# Every sample's payload is encrypted and authenticated (AES-GCM) in any case, and discovery is encrypted.
# --submessages chooses what also protects the RTPS submessage around each payload (writer id, sequence number):
# none (the default), sign (a MAC) or encrypt (a second AES-GCM pass). The README's DDS-Security section gives what
# each costs (encrypt doubles the fusion service's CPU per sample) and what it adds.
set -euo pipefail

usage() { sed -n '2,/^set -e/p' "$0" | grep '^#' | sed 's/^# \{0,1\}//'; }
submessages=none body=
while [ $# -gt 0 ]; do
  case $1 in
    --submessages)
      case ${2:-} in
        encrypt|sign|none) submessages=$2; shift 2 ;;
        *) echo "make-pki: error: --submessages takes encrypt, sign or none, not '${2:-}'" >&2; exit 2 ;;
      esac ;;
    --body)
      [ -f "${2:-}" ] || { echo "make-pki: error: --body takes a body model file, not '${2:-}'" >&2; exit 2; }
      body=$2; shift 2 ;;
    *) break ;;
  esac
done
if [ $# -lt 1 ] || [ "$1" = "-h" ] || [ "$1" = "--help" ]; then usage; exit 2; fi
out=$1; shift
metadata_protection=$(echo "$submessages" | tr '[:lower:]' '[:upper:]')
identities=("$@")
command -v openssl >/dev/null || { echo "make-pki: error: openssl is not installed (apt install openssl)" >&2; exit 1; }

# The node ids of a body model, as `bsn fusion --print-body` gives them ($BSN, else bsn on the PATH, else this
# checkout's build/bsn).
body_nodes() {
  local bsn=${BSN:-}
  [ -n "$bsn" ] || bsn=$(command -v bsn || true)
  [ -n "$bsn" ] || bsn=$(dirname "$0")/../../build/bsn
  [ -x "$bsn" ] || { echo "make-pki: error: cannot find the bsn program to read the body model (set BSN=PATH)" >&2; exit 1; }
  "$bsn" fusion --print-body ${body:+--body "$body"} | sed -n 's/^ *node: *\([^ #]*\).*/\1/p'
}
if [ -n "$body" ] || [ ${#identities[@]} -eq 0 ]; then
  nodes=$(body_nodes) || exit 1
  [ -n "$nodes" ] || { echo "make-pki: error: no node ids in the body model ${body:-(the default)}" >&2; exit 2; }
  for node in $nodes; do identities+=("sensor-$node:sensor:$node"); done
fi
if [ $# -eq 0 ]; then
  identities+=(fusion:fusion calibration:calibration viewer:viewer operator:operator recorder:recorder)
fi

# Topics each role may publish and subscribe to (DDS topic names; permissions list them literally).
role_topics() {  # role -> "publish|subscribe", space-separated topic lists
  case $1 in
    sensor)      echo "bsn/truth/orientation bsn/truth/segment_orientation bsn/truth/joint_angles|" ;;  # bsn/raw: in its nodes' partitions
    fusion)      echo "bsn/orientation bsn/joint_angles bsn/status|bsn/raw bsn/calibration/result bsn/status" ;;
    calibration) echo "bsn/calibration/result bsn/calibration/progress bsn/status|bsn/raw bsn/calibration/request" ;;
    viewer)      echo "|bsn/orientation bsn/joint_angles bsn/status bsn/truth/orientation bsn/truth/segment_orientation bsn/truth/joint_angles" ;;
    ros2-bridge) echo "rt/tf rt/bsn/*|bsn/raw bsn/orientation bsn/joint_angles" ;;
    operator)    echo "bsn/calibration/request|bsn/calibration/progress bsn/calibration/result bsn/status" ;;
    recorder)    echo "|bsn/*" ;;
    tester)      echo "bsn/truth/orientation bsn/truth/segment_orientation bsn/truth/joint_angles bsn/calibration/request|bsn/*" ;;  # + bsn/raw
    *) return 1 ;;
  esac
}

for id in "${identities[@]}"; do
  name=${id%%:*}; rest=${id#*:}; role=${rest%%:*}; id_nodes=${rest#*:}; [ "$id_nodes" != "$rest" ] || id_nodes=
  if [ "$name" = "$id" ] || ! [[ $name =~ ^[A-Za-z0-9_.-]+$ ]] || [ "$name" = ca ]; then
    echo "make-pki: error: '$id' is not NAME:ROLE (NAME of letters, digits, '_', '.', '-', not 'ca')" >&2; exit 2
  fi
  role_topics "$role" >/dev/null || { echo "make-pki: error: unknown role '$role' in '$id'" >&2; exit 2; }
  if [ "$role" = sensor ]; then
    # Node ids become partition names, which DDS matches as patterns: plain names only.
    [[ $id_nodes =~ ^[A-Za-z0-9_.-]+(,[A-Za-z0-9_.-]+)*$ ]] || {
      echo "make-pki: error: '$id': a sensor names the node ids it may write, NAME:sensor:NODE[,NODE...] (letters," \
           "digits, '_', '.', '-'), or use --body FILE" >&2; exit 2; }
  elif [ -n "$id_nodes" ]; then
    echo "make-pki: error: '$id': only a sensor identity names nodes" >&2; exit 2
  fi
done

mkdir -p "$out/ca"
ca_key=$out/ca/ca_key.pem ca_cert=$out/ca/ca.pem
if [ ! -f "$ca_key" ]; then
  openssl ecparam -name prime256v1 -genkey -noout -out "$ca_key"
  # DDS-Security checks the authority's certificate for digitalSignature, since it signs the documents too.
  openssl req -x509 -new -key "$ca_key" -sha256 -days 3650 -subj "/O=bsn/CN=bsn authority" -out "$ca_cert" \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign,digitalSignature"
  chmod 600 "$ca_key"
fi

domains="<domains><id_range><min>0</min><max>232</max></id_range></domains>"
# Only authenticated participants join; discovery, liveliness and every payload are encrypted; each topic is
# read- and write-controlled by the permissions below.
cat > "$out/ca/governance.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_domain_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      $domains
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>$metadata_protection</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML

topic_list() { local t; for t in $1; do printf '<topic>%s</topic>' "$t"; done; }
partition_list() { local p parts; IFS=, read -r -a parts <<< "$1"; for p in "${parts[@]}"; do printf '<partition>%s</partition>' "$p"; done; }

# Identities made earlier stay in the permissions (their role and nodes are remembered in OUT_DIR/NAME/).
for id in "${identities[@]}"; do
  name=${id%%:*}; rest=${id#*:}; role=${rest%%:*}; id_nodes=${rest#*:}; [ "$id_nodes" != "$rest" ] || id_nodes=
  mkdir -p "$out/$name"; echo "$role" > "$out/$name/role"
  if [ -n "$id_nodes" ]; then echo "$id_nodes" > "$out/$name/nodes"; else rm -f "$out/$name/nodes"; fi
done

{
  echo '<?xml version="1.0" encoding="UTF-8"?>'
  echo '<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'
  echo '     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170801/omg_shared_ca_permissions.xsd">'
  echo '  <permissions>'
  for dir in "$out"/*/; do
    name=$(basename "$dir"); [ "$name" != ca ] && [ -f "$dir/role" ] || continue
    role=$(cat "$dir/role"); topics=$(role_topics "$role")
    pub=${topics%%|*}; sub=${topics#*|}
    echo "    <grant name=\"$name\">"
    echo "      <subject_name>CN=$name,O=bsn</subject_name>"
    echo "      <validity><not_before>2020-01-01T00:00:00</not_before><not_after>2036-01-01T00:00:00</not_after></validity>"
    echo "      <allow_rule>"
    echo "        $domains"
    raw_partitions=
    [ "$role" = sensor ] && raw_partitions=$(cat "$dir/nodes" 2>/dev/null || true)
    [ "$role" = tester ] && raw_partitions='*'
    [ -n "$raw_partitions" ] &&
      echo "        <publish><topics><topic>bsn/raw</topic></topics><partitions>$(partition_list "$raw_partitions")</partitions></publish>"
    [ -n "$pub" ] && echo "        <publish><topics>$(topic_list "$pub")</topics></publish>"
    # Readers of bsn/raw read every node's partition ('*' also allows the default partition of the other topics).
    [ -n "$sub" ] &&
      echo "        <subscribe><topics>$(topic_list "$sub")</topics><partitions><partition>*</partition></partitions></subscribe>"
    echo "      </allow_rule>"
    echo "      <default>DENY</default>"
    echo "    </grant>"
  done
  echo '  </permissions>'
  echo '</dds>'
} > "$out/ca/permissions.xml"

sign() { openssl smime -sign -text -in "$1" -out "$2" -signer "$ca_cert" -inkey "$ca_key"; }
sign "$out/ca/governance.xml" "$out/ca/governance.p7s"
sign "$out/ca/permissions.xml" "$out/ca/permissions.p7s"

for dir in "$out"/*/; do
  name=$(basename "$dir"); [ "$name" != ca ] && [ -f "$dir/role" ] || continue
  if [ ! -f "$dir/key.pem" ]; then
    openssl ecparam -name prime256v1 -genkey -noout -out "$dir/key.pem"
    chmod 600 "$dir/key.pem"
    openssl req -new -key "$dir/key.pem" -subj "/O=bsn/CN=$name" -out "$dir/cert.csr"
    openssl x509 -req -in "$dir/cert.csr" -CA "$ca_cert" -CAkey "$ca_key" -CAcreateserial -sha256 -days 3650 \
      -out "$dir/cert.pem" 2>/dev/null
    rm -f "$dir/cert.csr"
  fi
  cp "$ca_cert" "$dir/ca.pem"
  cp "$out/ca/governance.p7s" "$out/ca/permissions.p7s" "$dir/"
done
echo "make-pki: identities in $out: $(cd "$out" && for d in */; do [ -f "$d/role" ] && printf '%s(%s) ' "${d%/}" "$(cat "$d/role")"; done)"
