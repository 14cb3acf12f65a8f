#!/usr/bin/env bash
# Makes an SROS2 keystore with openssl, laid out as `ros2 security create_keystore`
# and `ros2 security create_enclave` lay it out (ROS 2 Jazzy's sros2):
#
#   KEYSTORE/public/{ca,identity_ca,permissions_ca}.cert.pem   one CA for both roles
#   KEYSTORE/private/ca.key.pem
#   KEYSTORE/enclaves/governance.{xml,p7s}
#   KEYSTORE/enclaves/ENCLAVE/{identity_ca.cert.pem,permissions_ca.cert.pem,
#       governance.p7s,cert.pem,key.pem,permissions.xml,permissions.p7s}
#
#   bash tools/sros2_keystore.sh KEYSTORE                 create the keystore (if absent)
#   bash tools/sros2_keystore.sh KEYSTORE ENCLAVE [PUB]   add an enclave, e.g. /garment_sim
#
# Keys are ECDSA P-256, signatures SHA-256; governance and permissions are
# S/MIME-signed (PKCS#7, detached, text) by the permissions CA. The governance
# (written when the keystore is created) is sros2's: unauthenticated
# participants refused, join access control, read and write access control
# on every topic, and protection kinds taken from the environment, sros2's
# by default: DISCOVERY_PROTECTION=ENCRYPT, LIVELINESS_PROTECTION=ENCRYPT,
# RTPS_PROTECTION=SIGN, METADATA_PROTECTION=ENCRYPT, DATA_PROTECTION=ENCRYPT
# (NONE, SIGN, ENCRYPT, ..._WITH_ORIGIN_AUTHENTICATION; for RustDDS 0.15.1
# peers: RTPS_PROTECTION=ENCRYPT DATA_PROTECTION=NONE, docs/ros.md). An
# enclave may subscribe to every topic; it may publish on the DDS topics
# matching PUB (a space-separated list of fnmatch patterns, default `*`:
# all), e.g. "rt/obstacles rq/* ros_discovery_info". Its certificate's
# subject and its grant's subject are `CN=ENCLAVE`.
set -euo pipefail
ks=${1:?usage: sros2_keystore.sh KEYSTORE [ENCLAVE [PUB]]}
days=3650
domains='<domains><id_range><min>0</min><max>230</max></id_range></domains>'

sign() { # sign IN.xml OUT.p7s
    openssl smime -sign -text -in "$1" -out "$2" \
        -signer "$ks/public/permissions_ca.cert.pem" -inkey "$ks/private/ca.key.pem"
}

if [ ! -f "$ks/public/ca.cert.pem" ]; then
    mkdir -p "$ks/public" "$ks/private" "$ks/enclaves"
    openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -sha256 \
        -days "$days" -subj "/CN=sros2testCA" \
        -keyout "$ks/private/ca.key.pem" -out "$ks/public/ca.cert.pem" 2>/dev/null
    cp "$ks/public/ca.cert.pem" "$ks/public/identity_ca.cert.pem"
    cp "$ks/public/ca.cert.pem" "$ks/public/permissions_ca.cert.pem"
    cat > "$ks/enclaves/governance.xml" <<GOV
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      $domains
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>${DISCOVERY_PROTECTION:-ENCRYPT}</discovery_protection_kind>
      <liveliness_protection_kind>${LIVELINESS_PROTECTION:-ENCRYPT}</liveliness_protection_kind>
      <rtps_protection_kind>${RTPS_PROTECTION:-SIGN}</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>${METADATA_PROTECTION:-ENCRYPT}</metadata_protection_kind>
          <data_protection_kind>${DATA_PROTECTION:-ENCRYPT}</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
GOV
    sign "$ks/enclaves/governance.xml" "$ks/enclaves/governance.p7s"
    echo "sros2_keystore: keystore $ks"
fi

[ $# -ge 2 ] || exit 0
enclave=$2
pub=${3:-*}
case $enclave in /*) ;; *) echo "sros2_keystore: enclave $enclave must start with /" >&2; exit 2 ;; esac
dir=$ks/enclaves/${enclave#/}
mkdir -p "$dir"
cp "$ks/public/identity_ca.cert.pem" "$ks/public/permissions_ca.cert.pem" "$ks/enclaves/governance.p7s" "$dir/"
openssl req -new -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -sha256 \
    -subj "/CN=\\${enclave}" -keyout "$dir/key.pem" -out "$dir/req.pem" 2>/dev/null
openssl x509 -req -sha256 -days "$days" -in "$dir/req.pem" -CA "$ks/public/identity_ca.cert.pem" \
    -CAkey "$ks/private/ca.key.pem" -set_serial "0x$(openssl rand -hex 8)" -out "$dir/cert.pem" 2>/dev/null
rm "$dir/req.pem"
topics() { local IFS=" "; set -f; for p in $1; do printf "<topic>%s</topic>" "$p"; done; set +f; }
from=$(date -u +%Y-%m-%dT%H:%M:%S)
until=$(date -u -d "+$days days" +%Y-%m-%dT%H:%M:%S)
cat > "$dir/permissions.xml" <<PERM
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$enclave">
      <subject_name>CN=$enclave</subject_name>
      <validity><not_before>$from</not_before><not_after>$until</not_after></validity>
      <allow_rule>
        $domains
        <publish><topics>$(topics "$pub")</topics></publish>
        <subscribe><topics><topic>*</topic></topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
PERM
sign "$dir/permissions.xml" "$dir/permissions.p7s"
echo "sros2_keystore: enclave $enclave in $dir (publishes: $pub)"
