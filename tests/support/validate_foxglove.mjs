// Validates exported Foxglove messages against Foxglove's published JSON Schemas
// (`@foxglove/schemas`) with ajv, a JSON Schema validator; tests/export.rs runs it.
//
// Usage: node validate_foxglove.mjs NODE_ENV_DIR [--versions]
//   NODE_ENV_DIR  where scripts/node-env.sh installed the packages (target/node-env)
//   --versions    only load the packages and print their versions (is everything there?)
//
// Input, on stdin, one JSON object a line:
//   {"channel", "schema_name", "schema_encoding", "message_encoding", "schema"}  a channel, before
//       its messages; `schema` is the schema text the file holds
//   {"channel", "index", "data"}  a message: its index on its channel and its bytes as text
// Output, on stdout, one JSON object: per channel whether the file's schema is the published one
// (`schemas`), the messages validated (`validated`) and failed (`failed`), and the failures
// themselves (`failures`: channel, index, ajv's errors), at most FAILURES_SHOWN per channel.

import { createRequire } from "node:module";
import { isDeepStrictEqual } from "node:util";
import { resolve } from "node:path";
import { createInterface } from "node:readline";

const FAILURES_SHOWN = 5;
const [envDir, flag] = process.argv.slice(2);
const require = createRequire(resolve(envDir ?? ".", "package.json"));
const published = require("@foxglove/schemas/jsonschema");
const Ajv = require("ajv");

if (flag === "--versions") {
  const version = (p) => require(`${p}/package.json`).version;
  console.log(JSON.stringify({ "@foxglove/schemas": version("@foxglove/schemas"), ajv: version("ajv") }));
  process.exit(0);
}

const ajv = new Ajv({ allErrors: true, strict: true });
const channels = new Map();
const report = { schemas: {}, validated: {}, failed: {}, failures: [] };

/// The published schema of a `foxglove.NAME`, or why there is none.
function publishedSchema(name) {
  const short = typeof name === "string" && name.startsWith("foxglove.") ? name.slice(9) : null;
  const schema = short && published[short];
  return schema && schema.title === name ? { schema } : { why: `no published schema named ${name}` };
}

function openChannel(line) {
  const { channel, schema_name, schema_encoding, message_encoding, schema } = line;
  const problems = [];
  if (schema_encoding !== "jsonschema") problems.push(`schema encoding ${schema_encoding}, expected jsonschema`);
  if (message_encoding !== "json") problems.push(`message encoding ${message_encoding}, expected json`);
  const found = publishedSchema(schema_name);
  let validate = null;
  if (found.schema) {
    let written = null;
    try {
      written = JSON.parse(schema);
    } catch (e) {
      problems.push(`the file's schema is not JSON: ${e.message}`);
    }
    if (written !== null && !isDeepStrictEqual(written, found.schema)) {
      problems.push(`the file's schema ${schema_name} differs from the published one`);
    }
    validate = ajv.compile(found.schema);
  } else {
    problems.push(found.why);
  }
  report.schemas[channel] = problems.length === 0 ? "published" : problems.join("; ");
  report.validated[channel] = 0;
  report.failed[channel] = 0;
  channels.set(channel, validate);
}

function fail(channel, index, errors) {
  report.failed[channel] += 1;
  if (report.failed[channel] <= FAILURES_SHOWN) report.failures.push({ channel, index, errors });
}

function checkMessage({ channel, index, data }) {
  if (!channels.has(channel)) {
    report.failures.push({ channel, index, errors: ["a message before its channel"] });
    return;
  }
  const validate = channels.get(channel);
  report.validated[channel] += 1;
  let message;
  try {
    message = JSON.parse(data);
  } catch (e) {
    return fail(channel, index, [`not JSON: ${e.message}`]);
  }
  if (validate === null) return fail(channel, index, ["no published schema to validate against"]);
  if (!validate(message)) {
    fail(
      channel,
      index,
      validate.errors.map((e) => `${e.instancePath || "/"} ${e.message} ${JSON.stringify(e.params)}`),
    );
  }
}

for await (const text of createInterface({ input: process.stdin, crlfDelay: Infinity })) {
  if (text.trim() === "") continue;
  const line = JSON.parse(text);
  if ("schema" in line) openChannel(line);
  else checkMessage(line);
}
console.log(JSON.stringify(report));
