// Receive OSC over UDP with the npm `osc` package and print what it decoded (tests/test_vmc.py).
// Usage: node tests/osc_receive.js PORT COUNT TIMEOUT_MS
// Listens on 127.0.0.1:PORT (0 = any free port) and prints one JSON line {"port": p} once
// listening, then one JSON line per message, bundles unpacked:
// {"address", "types" (OSC type tags), "args" (values), "timeTag" ([secs, frac] of the
// enclosing bundle, null outside one), "size" (bytes of the datagram it came in)}.
// Exits 0 after COUNT messages, 1 after TIMEOUT_MS or on an error (reported on stderr).
// The module is found through NODE_PATH (tests/test_vmc.py installs it into a cache folder).
const osc = require('osc');
const [port, count, timeoutMs] = process.argv.slice(2, 5).map(Number);
const udp = new osc.UDPPort({localAddress: '127.0.0.1', localPort: port, metadata: true});
let seen = 0;
function stop(error) {
  clearTimeout(timer);
  if (error) { console.error(error); process.exitCode = 1; }
  udp.close();
}
const timer = setTimeout(() => stop(`timeout after ${seen} of ${count} messages`), timeoutMs);
udp.on('ready', () => console.log(JSON.stringify({port: udp.socket.address().port})));
udp.on('message', (message, timeTag, info) => {
  console.log(JSON.stringify({
    address: message.address,
    types: message.args.map(a => a.type).join(''),
    args: message.args.map(a => a.value),
    timeTag: timeTag ? timeTag.raw : null,
    size: info.size,
  }));
  if (++seen === count) stop();
});
udp.on('error', e => stop(String(e)));
udp.open();
