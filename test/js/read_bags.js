// Foxglove's readers on the bags given (MCAP files or rosbag2 directories): prints one JSON
// object, per path what they read. Run by test/test_foxglove_readers.py.
//
// Each MCAP file is read twice: walked record by record by @mcap/core's McapStreamReader
// (every chunk's CRC checked) and through its summary by McapIndexedReader (as Foxglove
// opens a file; CRCs checked); every message is decoded by @foxglove/rosmsg2-serialization
// with the definitions @foxglove/rosmsg parses from the file's schema text. A channel's
// offered QoS is read by @foxglove/rosbag2's parseQosProfiles, a directory's metadata.yaml
// and the rosbag2 record's serialized_metadata by its parseYaml.
"use strict";

const fs = require("fs");
const path = require("path");
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { loadDecompressHandlers } = require("@mcap/support");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const { parseQosProfiles, parseYaml } = require("@foxglove/rosbag2");

function plain(value) {
  // BigInts (parseYaml's integers, MCAP's times) as numbers or strings for JSON.
  return JSON.parse(JSON.stringify(value, (_, v) =>
    typeof v === "bigint" ? (Number.isSafeInteger(Number(v)) ? Number(v) : v.toString()) : v));
}

function decoderFor(schema, decoders) {
  if (!decoders.has(schema.id)) {
    const text = new TextDecoder().decode(schema.data);
    decoders.set(schema.id, new MessageReader(parse(text, { ros2: true })));
  }
  return decoders.get(schema.id);
}

function streamRead(data, handlers) {
  const reader = new McapStreamReader({ validateCrcs: true, decompressHandlers: handlers });
  reader.append(data);
  const schemas = new Map(), channels = new Map(), decoders = new Map();
  const counts = {}, metadata = [], out = { decoded: 0, trailing: 0 };
  for (let record; (record = reader.nextRecord()); ) {
    if (record.type === "Schema") schemas.set(record.id, record);
    else if (record.type === "Channel") channels.set(record.id, record);
    else if (record.type === "Metadata") metadata.push(record.name);
    else if (record.type === "Message") {
      const channel = channels.get(record.channelId);
      counts[channel.topic] = (counts[channel.topic] || 0) + 1;
      const decoder = decoderFor(schemas.get(channel.schemaId), decoders);
      decoder.readMessage(record.data);
      out.decoded += 1;
      if (decoder.lastReadHadTrailingBytes()) out.trailing += 1;
    }
  }
  out.done = reader.done();
  out.counts = counts;
  out.metadata = metadata;
  out.schemas = [...schemas.values()].map((s) => [s.name, s.encoding]);
  out.qos = {};
  for (const channel of channels.values()) {
    const profiles = parseQosProfiles(channel.metadata.get("offered_qos_profiles") || "");
    // [reliability, durability, whether deadline, lifespan and lease are infinite]
    out.qos[channel.topic] = profiles.map((p) => [p.reliability, p.durability,
      p.deadline === undefined && p.lifespan === undefined &&
      p.livelinessLeaseDuration === undefined]);
  }
  return out;
}

async function indexedRead(data, handlers) {
  const readable = {
    size: async () => BigInt(data.length),
    read: async (offset, length) => data.subarray(Number(offset), Number(offset + length)),
  };
  const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers: handlers });
  const counts = {}, decoders = new Map();
  let decoded = 0;
  for await (const message of reader.readMessages({ validateCrcs: true })) {
    const channel = reader.channelsById.get(message.channelId);
    counts[channel.topic] = (counts[channel.topic] || 0) + 1;
    decoderFor(reader.schemasById.get(channel.schemaId), decoders).readMessage(message.data);
    decoded += 1;
  }
  const metadata = [];
  let rosbag2 = null;
  for await (const record of reader.readMetadata()) {
    metadata.push(record.name);
    if (record.name === "rosbag2") rosbag2 = parseYaml(record.metadata.get("serialized_metadata"));
  }
  return {
    counts, decoded, metadata, rosbag2: plain(rosbag2),
    statistics: plain(reader.statistics ? {
      messageCount: reader.statistics.messageCount,
      channelMessageCounts: Object.fromEntries([...reader.statistics.channelMessageCounts]
        .map(([id, n]) => [reader.channelsById.get(id).topic, n])),
      metadataCount: reader.statistics.metadataCount,
    } : null),
  };
}

async function readFile(file, handlers) {
  const data = fs.readFileSync(file);
  const result = { file: path.basename(file), errors: [] };
  try {
    result.stream = streamRead(data, handlers);
  } catch (error) {
    result.errors.push(`stream: ${error.message}`);
  }
  try {
    result.indexed = await indexedRead(data, handlers);
  } catch (error) {
    result.errors.push(`indexed: ${error.message}`);
  }
  return result;
}

async function main() {
  const handlers = await loadDecompressHandlers();
  const output = {};
  for (const target of process.argv.slice(2)) {
    const entry = { files: [] };
    let files = [target];
    if (fs.statSync(target).isDirectory()) {
      const yamlPath = path.join(target, "metadata.yaml");
      if (fs.existsSync(yamlPath)) {
        const info = plain(parseYaml(fs.readFileSync(yamlPath, "utf8")))
          .rosbag2_bagfile_information;
        entry.yaml = {
          version: info.version,
          relative_file_paths: info.relative_file_paths,
          message_count: info.message_count,
          counts: Object.fromEntries(info.topics_with_message_count.map(
            (t) => [t.topic_metadata.name, t.message_count])),
          qos: Object.fromEntries(info.topics_with_message_count.map(
            (t) => [t.topic_metadata.name, t.topic_metadata.offered_qos_profiles])),
          custom_data: info.custom_data,
          ros_distro: info.ros_distro,
        };
        files = info.relative_file_paths.map((name) => path.join(target, name));
      } else {
        files = fs.readdirSync(target).filter((name) => name.endsWith(".mcap")).sort()
          .map((name) => path.join(target, name));
      }
    }
    for (const file of files) entry.files.push(await readFile(file, handlers));
    output[target] = entry;
  }
  process.stdout.write(JSON.stringify(output));
}

main().catch((error) => {
  process.stderr.write(`read_bags.js: ${error.stack || error}\n`);
  process.exit(1);
});
