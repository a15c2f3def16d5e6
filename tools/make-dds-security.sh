#!/bin/sh
# Creates DDS Security material for a tarmac deployment or test (docs/operations.md "DDS Security"):
#
#   tools/make-dds-security.sh OUTDIR [--protection sign|encrypt|none] [--days N]
#                                     [--vehicles "ID ID ..."]
#
# OUTDIR/ca.cert.pem            the CA: identity CA and permissions CA (dds.security.identity_ca,
#                               dds.security.permissions_ca)
# OUTDIR/ca.key.pem             the CA's private key: keep it off the vehicle
# OUTDIR/governance.xml|.p7s    domain rules 0..232, signed by the CA (dds.security.governance)
# OUTDIR/permissions.xml|.p7s   one grant per identity below, signed (dds.security.permissions)
# OUTDIR/<id>/cert.pem, key.pem identity certificate and private key of each participant
#                               (dds.security.identity_certificate, dds.security.private_key)
#
# Identities (subject "CN=<id>,O=tarmac") and what their grant allows on the default topics
# (DESIGN.md section 5; if the config renames topics, edit permissions.xml and re-sign it):
#   tarmacd    subscribes LiDAR, pose, pose corrections, virtual obstacles; publishes costmap, ESDF slices,
#              CycleReport, DiagnosticArray
#   publisher  publishes LiDAR, pose and pose corrections (tarmac-replay, a localisation stack, LiDAR drivers)
#   obstacles  publishes virtual obstacles; subscribes the costmap
#   monitor    subscribes every tarmac topic, publishes nothing (tarmac-audit, tarmac-echo,
#              tarmac-fleet: the fleet summaries of every vehicle)
#   tarmacd-<ID>  with --vehicles, one per vehicle: tarmacd's grant, plus the fleet summaries
#              (rt/tarmac/fleet/bev, docs/fleet.md): published in the DDS partition
#              tarmac_fleet_<ID> only, subscribed in tarmac_fleet_*. tarmacd refuses a summary whose
#              vehicle id is not its writer's partition, so with these grants a vehicle cannot
#              publish as another. Vehicle ids: 1..64 of [A-Za-z0-9_-] (fleet.vehicle_id).
#
# Governance: unauthenticated participants are refused, joining needs a valid permissions grant,
# discovery and liveliness are encrypted, read and write access control is on for every topic.
# --protection chooses how every RTPS message (user data included) is protected: sign (default;
# integrity and origin authentication with AES-GMAC, data readable on the wire), encrypt
# (AES-GCM: confidentiality too) or none (authentication and access control only). The
# protection is per RTPS message (rtps_protection_kind), not per sample (data_protection_kind
# NONE): Fast DDS 2.9.1 cannot decode a payload-protected sample that is fragmented ("Error
# decoding encoded payload"; a 320 kB PointCloud2 never arrives), so per-sample protection
# would silently drop every LiDAR scan.
# P-256 keys; takes well under a second. Test material: the CA key sits next to the rest.
set -eu

usage() {
  echo "usage: $0 OUTDIR [--protection sign|encrypt|none] [--days N] [--vehicles \"ID ID ...\"]" >&2
  exit 64
}
[ $# -ge 1 ] || usage
out=$1
shift
protection=sign
days=3650
vehicles=
while [ $# -gt 0 ]; do
  case $1 in
    --protection) [ $# -ge 2 ] || usage; protection=$2; shift 2 ;;
    --days) [ $# -ge 2 ] || usage; days=$2; shift 2 ;;
    --vehicles) [ $# -ge 2 ] || usage; vehicles=$2; shift 2 ;;
    *) usage ;;
  esac
done
case $protection in
  sign) kind=SIGN ;;
  encrypt) kind=ENCRYPT ;;
  none) kind=NONE ;;
  *) usage ;;
esac
for v in $vehicles; do
  case $v in
    *[!A-Za-z0-9_-]*) echo "$0: vehicle id '$v': only [A-Za-z0-9_-]" >&2; exit 64 ;;
  esac
  [ ${#v} -le 64 ] || { echo "$0: vehicle id '$v': more than 64 characters" >&2; exit 64; }
done
command -v openssl >/dev/null || { echo "$0: openssl not found" >&2; exit 69; }

mkdir -p "$out"
umask 077
cd "$out"

# ---- the CA (identity and permissions) ----
openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out ca.key.pem 2>/dev/null
openssl req -x509 -new -key ca.key.pem -sha256 -days "$days" -subj "/O=tarmac/CN=tarmac DDS CA" \
  -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,digitalSignature,keyCertSign,cRLSign" \
  -out ca.cert.pem
chmod 644 ca.cert.pem

# ---- one identity per participant ----
identities="tarmacd publisher obstacles monitor"
for v in $vehicles; do identities="$identities tarmacd-$v"; done
for id in $identities; do
  mkdir -p "$id"
  openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$id/key.pem" 2>/dev/null
  openssl req -new -key "$id/key.pem" -subj "/O=tarmac/CN=$id" -out "$id/csr.pem"
  openssl x509 -req -in "$id/csr.pem" -CA ca.cert.pem -CAkey ca.key.pem -CAcreateserial \
    -days "$days" -sha256 -out "$id/cert.pem" 2>/dev/null
  rm "$id/csr.pem"
  chmod 644 "$id/cert.pem"
done
rm -f ca.cert.srl

# ---- governance: what the domain protects ----
cat > governance.xml <<EOF
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>0</min><max>232</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>$kind</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>NONE</metadata_protection_kind>
          <data_protection_kind>NONE</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
EOF

# ---- permissions: who may publish and subscribe what ----
not_before=$(date -u -d "-1 day" +%Y-%m-%dT%H:%M:%S)  # a day of slack for clock skew
not_after=$(date -u -d "+$days days" +%Y-%m-%dT%H:%M:%S)
topics() {  # topics TOPIC... -> <topics> element
  printf '<topics>'
  for t in "$@"; do printf '<topic>%s</topic>' "$t"; done
  printf '</topics>'
}
lidar='rt/tarmac/lidar/*/points'
pose=rt/tarmac/pose
correction=rt/tarmac/pose_correction
obstacles=rt/tarmac/virtual_obstacles
costmap=rt/tarmac/costmap
slice=rt/tarmac/esdf_slice
band=rt/tarmac/esdf_band
debris=rt/tarmac/debris
report=rt/tarmac/diagnostics
diag=rt/diagnostics
fleet=rt/tarmac/fleet/bev
in_partition() {  # in_partition PARTITION TOPIC... -> <topics> and <partitions> elements
  p=$1
  shift
  topics "$@"
  printf '<partitions><partition>%s</partition></partitions>' "$p"
}
grant() {  # grant ID PUBLISH_TOPICS SUBSCRIBE_TOPICS [PUBLISH2 SUBSCRIBE2] (rendered, may be empty)
  subject=$(openssl x509 -in "$1/cert.pem" -noout -subject -nameopt RFC2253 | sed 's/^subject=//')
  echo "    <grant name=\"$1\">"
  echo "      <subject_name>$subject</subject_name>"
  echo "      <validity><not_before>$not_before</not_before><not_after>$not_after</not_after></validity>"
  echo "      <allow_rule>"
  echo "        <domains><id_range><min>0</min><max>232</max></id_range></domains>"
  [ -z "$2" ] || echo "        <publish>$2</publish>"
  [ -z "$3" ] || echo "        <subscribe>$3</subscribe>"
  [ -z "${4:-}" ] || echo "        <publish>$4</publish>"
  [ -z "${5:-}" ] || echo "        <subscribe>$5</subscribe>"
  echo "      </allow_rule>"
  echo "      <default>DENY</default>"
  echo "    </grant>"
}
{
  echo '<?xml version="1.0" encoding="UTF-8"?>'
  echo '<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'
  echo '     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">'
  echo '  <permissions>'
  grant tarmacd "$(topics "$costmap" "$slice" "$band" "$debris" "$report" "$diag")" \
    "$(topics "$lidar" "$pose" "$correction" "$obstacles")"
  grant publisher "$(topics "$lidar" "$pose" "$correction")" ""
  grant obstacles "$(topics "$obstacles")" "$(topics "$costmap")"
  grant monitor "" "$(topics "$lidar" "$pose" "$correction" "$obstacles" "$costmap" "$slice" "$band" "$debris" "$report" "$diag")" \
    "" "$(in_partition 'tarmac_fleet_*' "$fleet")"
  for v in $vehicles; do
    grant "tarmacd-$v" "$(topics "$costmap" "$slice" "$band" "$debris" "$report" "$diag")" \
      "$(topics "$lidar" "$pose" "$correction" "$obstacles")" \
      "$(in_partition "tarmac_fleet_$v" "$fleet")" "$(in_partition 'tarmac_fleet_*' "$fleet")"
  done
  echo '  </permissions>'
  echo '</dds>'
} > permissions.xml

for doc in governance permissions; do
  openssl smime -sign -in "$doc.xml" -text -out "$doc.p7s" -signer ca.cert.pem -inkey ca.key.pem
done
chmod 644 governance.xml governance.p7s permissions.xml permissions.p7s
echo "DDS Security material in $out ($protection): CA, governance, permissions; identities: $identities"
