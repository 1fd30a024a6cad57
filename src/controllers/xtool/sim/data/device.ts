/**
 * What the simulated laser says about itself. Values copied from the fixtures
 * (tests/fixtures/xtool/d-series/http, doc examples from a D1 Pro, firmware V40.31.006.01);
 * the MAC and serial placeholders of the document are replaced by obviously fake values.
 */
export const DEVICE = {
  machineType: 'xTool D1Pro',
  laserPower: 10,
  laserPowerInfoType: 0,
  version: 'V40.31.006.01 B2',
  sn: 'SIM0000000000001',
  mac: '02:00:00:5E:00:01',
  name: 'My xTool D1 Pro',
  offset: { x: 0.0, y: 0.0 },
  dotMode: 0,
  periphery: {
    status: 'normal',
    limitStopFlag: 1,
    tiltStopFlag: 1,
    movingStopFlag: 1,
    tiltThreshold: 15,
    movingThreshold: 40,
    flameAlarmMode: 3,
    flameAlarmSensitivity: 1,
  },
} as const;

/** A small engraving job: a framed square with a hatch fill, `lines` lines long. */
export function demoJob(lines = 600): string {
  const out = ['; Shopdeck simulated demo job (not a real file)', 'G90', 'G21', 'M17', 'G0 X10 Y10', 'M3 S0'];
  let y = 10;
  while (out.length < lines - 4) {
    out.push(`G1 X60 Y${y.toFixed(1)} S600 F3000`, `G0 X10 Y${(y + 0.1).toFixed(1)}`);
    y += 0.1;
  }
  out.push('M5', 'G0 X0 Y0', 'M18');
  return out.join('\n') + '\n';
}

/** A framing file: the outline of the demo job. */
export const DEMO_FRAME = ['G90', 'G0 X10 Y10', 'G1 X60 Y10 S1', 'G1 X60 Y60', 'G1 X10 Y60', 'G1 X10 Y10', 'G0 X0 Y0'].join('\n') + '\n';
