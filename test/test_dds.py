"""DDS confinement defaults (ROS-free checks of the settings and the profile)."""

import os
import xml.etree.ElementTree as ET

from clusterfilter_ros.dds import apply_loopback_defaults, loopback_settings

NS = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}


def test_test_session_is_confined():
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert 100 <= int(os.environ["ROS_DOMAIN_ID"]) <= 200
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"].endswith("fastdds_loopback.xml")


def test_defaults_do_not_override_user_choice():
    env = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    applied = apply_loopback_defaults(env, domain_id=150)
    assert applied["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "SUBNET"
    assert applied["ROS_DOMAIN_ID"] == "150"
    assert env["RMW_IMPLEMENTATION"] == "rmw_fastrtps_cpp"


def test_profile_is_loopback_and_large_shm():
    tree = ET.parse(loopback_settings()["FASTRTPS_DEFAULT_PROFILES_FILE"])
    descriptors = tree.findall(".//f:transport_descriptor", NS)
    kinds = {d.find("f:type", NS).text: d for d in descriptors}
    assert set(kinds) == {"SHM", "UDPv4"}
    assert int(kinds["SHM"].find("f:segment_size", NS).text) >= 8 * 1024 * 1024
    addresses = [a.text for a in kinds["UDPv4"].findall(".//f:address", NS)]
    assert addresses == ["127.0.0.1"]
    assert tree.find(".//f:useBuiltinTransports", NS).text == "false"
    peers = [a.text for a in tree.findall(".//f:initialPeersList//f:address", NS)]
    assert peers == ["127.0.0.1"]
