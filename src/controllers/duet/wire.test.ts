import { describe, expect, it } from 'vitest';
import { fixtureJson, fixtureText } from './fixtures.test-util';
import { applyPatch, type JsonObject } from './patch';
import {
  directoryListing,
  messageBoxSchema,
  objectModelSchema,
  parseHeightMap,
  parsedFileInfoSchema,
} from './wire';

describe('object model schema', () => {
  it('parses the real geminiv2 model', () => {
    const m = objectModelSchema.parse(fixtureJson('object-model/model_geminiv2.json'));
    expect(m.state.status).toBe('idle');
    expect(m.state.machineMode).toBe('FFF');
    expect(m.boards[0]?.name).toBe('fly_geminiv2.0');
    expect(m.boards[0]?.mcuTemp?.current).toBe(47.1);
    expect(m.heat.bedHeaters).toEqual([0, -1, -1, -1]);
    expect(m.heat.heaters.map((h) => h?.current)).toEqual([-273.15, -273.15]);
    expect(m.move.axes.map((a) => a?.letter)).toEqual(['X', 'Y', 'Z']);
    expect(m.job.file?.fileName).toBeNull();
    expect(m.job.file?.size).toBe(0);
    expect(Object.keys(m.plugins).sort()).toEqual(['DuetPiManagementPlugin', 'EndstopsMonitor']);
    expect(m.plugins['DuetPiManagementPlugin']?.pid).toBe(1269);
    expect(m.volumes[0]?.freeSpace).toBe(23904288768);
    expect(m.directories.gCodes).toBe('0:/gcodes/');
    expect(m.sbc?.dsf?.version).toBe('3.5.0-rc.2');
    // unknown keys pass through
    expect((m as unknown as JsonObject)['limits']).toBeDefined();
  });

  it('parses the virgin (empty) model', () => {
    const m = objectModelSchema.parse(fixtureJson('object-model/model_virgin.json'));
    expect(m.boards).toEqual([]);
    expect(m.heat.heaters).toEqual([]);
    expect(m.sbc).toBeNull();
  });

  it('takes the job file with a thumbnail from the job patch', () => {
    const { model } = applyPatch(
      fixtureJson('object-model/model_geminiv2.json'),
      fixtureJson('patches/dsf-python/test_job_1__job-file-with-thumbnail.json'),
    );
    const m = objectModelSchema.parse(model);
    expect(m.job.file?.fileName).toBe('0:/gcodes/Veil_Token.gcode');
    expect(m.job.file?.numLayers).toBe(9);
    expect(m.job.file?.thumbnails[0]?.format).toBe('png');
    expect(m.job.file?.thumbnails[0]?.data?.startsWith('iVBORw0KGgo')).toBe(true);
  });

  it('is lenient: unknown enums, numeric strings, null holes', () => {
    const raw = fixtureJson('object-model/model_geminiv2.json');
    const { model } = applyPatch(raw, {
      state: { status: 'levitating', machineMode: 'Plasma', currentTool: '0' },
      heat: { heaters: [{ state: 'melting', current: '21.5' }, null] },
      tools: [null],
      newTopLevelThing: { a: 1 },
    });
    const m = objectModelSchema.parse(model);
    expect(m.state.status).toBe('unknown (raw levitating)');
    expect(m.state.machineMode).toBe('unknown (raw Plasma)');
    expect(m.state.currentTool).toBe(0);
    expect(m.heat.heaters[0]?.state).toBe('unknown (raw melting)');
    expect(m.heat.heaters[0]?.current).toBe(21.5);
    expect(m.heat.heaters[1]).toBeNull();
    expect(m.tools).toEqual([null]);
  });

  it('fails with a path on a model that is really broken', () => {
    const raw = fixtureJson('object-model/model_geminiv2.json');
    const { model } = applyPatch(raw, { move: { axes: [{ letter: 5 }] } });
    const r = objectModelSchema.safeParse(model);
    expect(r.success).toBe(false);
    expect(r.error?.issues[0]?.path.join('.')).toBe('move.axes.0.letter');
  });
});

describe('message box', () => {
  it('reads numeric modes and defaults', () => {
    const b = messageBoxSchema.parse({
      mode: '5',
      seq: 3,
      message: 'How many?',
      min: 1,
      max: '10',
      default: 4,
    });
    expect(b).toMatchObject({
      mode: 5,
      seq: 3,
      min: 1,
      max: 10,
      default: 4,
      cancelButton: false,
      axisControls: 0,
    });
  });
});

describe('files', () => {
  it('parses a directory listing as the document shows it', () => {
    const l = directoryListing.parse([
      { type: 'd', name: 'sys', date: '2019-10-21T23:47:59+01:00' },
      { type: 'f', name: 'some file.gcode', size: 23534, date: '2019-10-21T23:47:59+01:00' },
      { type: 'l', name: 'link' },
    ]);
    expect(l.map((e) => e.type)).toEqual(['d', 'f', 'unknown (raw l)']);
    expect(l[1]?.size).toBe(23534);
    expect(l[0]?.size).toBeNull();
  });
  it('parses file info', () => {
    const job = fixtureJson('patches/dsf-python/test_job_1__job-file-with-thumbnail.json')[
      'job'
    ] as JsonObject;
    const info = parsedFileInfoSchema.parse(job['file']);
    expect(info.printTime).toBe(798);
    expect(info.filament).toEqual([496.4]);
  });
  it('parses the real height map', () => {
    const hm = parseHeightMap(fixtureText('files/heightmap.csv'));
    expect(hm.xnum).toBe(6);
    expect(hm.ynum).toBe(6);
    expect(hm.points[0]?.[0]).toBeCloseTo(0.088);
    expect(hm.points[2]?.[4]).toBeCloseTo(-0.027);
    expect(() => parseHeightMap('hello\nworld\n1')).toThrow(/height map/i);
  });
});
