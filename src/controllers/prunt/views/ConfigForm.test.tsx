// @vitest-environment happy-dom
import { act, cleanup, fireEvent, render, screen, within } from '@testing-library/react';
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { afterEach, describe, expect, it } from 'vitest';
import { FormView, ReviewChanges } from '../../../forms/FormView';
import { FormModel } from '../../../forms/model';
import { buildForm, placeErrors, readValues } from '../config-ir';
import { configSchemaSchema, configValuesSchema } from '../wire';

const dir = join(process.cwd(), 'tests/fixtures/prunt');
const json = (f: string): unknown => JSON.parse(readFileSync(join(dir, f), 'utf8'));

function board3() {
  const pf = buildForm(configSchemaSchema.parse(json('config-schema.json')));
  const model = new FormModel(pf.form);
  model.setBase(readValues(pf, configValuesSchema.parse(json('config-values.json')).Values));
  return { pf, model };
}

afterEach(() => cleanup());

describe('the Board 3 config form', () => {
  it('validates as you type and badges the tab and the section that contain the error', () => {
    const { model } = board3();
    render(<FormView model={model} assetBase="/machines/p1" />);
    fireEvent.click(screen.getByTestId('section-Steppers'));
    const input = screen.getByTestId('field-Steppers$STEPPER_1$Run current') as HTMLInputElement;
    expect(input.value).toBe('1.2');
    expect(screen.getByTestId('row-Steppers$STEPPER_1$Run current').textContent).toContain(
      '≥ 0.125 · ≤ 3 amp',
    );
    fireEvent.change(input, { target: { value: '3.5' } });
    expect(screen.getByTestId('local-error-Steppers$STEPPER_1$Run current').textContent).toMatch(
      /Out of range/,
    );
    // On the tab and on the group's legend.
    expect(screen.getAllByTestId('errors-Steppers$STEPPER_1').map((b) => b.textContent)).toEqual(['1', '1']);
    expect(screen.getAllByTestId('errors-Steppers').map((b) => b.textContent)).toEqual(['1', '1']); // section nav + title
    fireEvent.change(input, { target: { value: '2.5' } });
    expect(screen.queryByTestId('local-error-Steppers$STEPPER_1$Run current')).toBeNull();
    expect(screen.queryAllByTestId('errors-Steppers')).toEqual([]);
  });

  it('shows "no limit" for ±1E100 and ratios as numerator : denominator', () => {
    const { model } = board3();
    render(<FormView model={model} assetBase="/machines/p1" />);
    fireEvent.click(screen.getByTestId('section-Steppers'));
    fireEvent.click(screen.getByTestId('ftab-Steppers$STEPPER_4'));
    expect(screen.getByTestId('row-Steppers$STEPPER_4$THIGH').textContent).toContain('≥ 0 · no upper limit');
    const num = screen.getByTestId(
      'field-Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio-num',
    ) as HTMLInputElement;
    const den = screen.getByTestId(
      'field-Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio-den',
    ) as HTMLInputElement;
    expect([num.value, den.value]).toEqual(['50', '17']);
    fireEvent.change(den, { target: { value: '0' } });
    expect(
      screen.getByTestId(
        'local-error-Steppers$STEPPER_4$Distance per step$Gear with circumference$Gear ratio',
      ).textContent,
    ).toMatch(/denominator must not be zero/);
  });

  it('switching a variant keeps the other choice and its values', () => {
    const { model } = board3();
    render(<FormView model={model} assetBase="/machines/p1" />);
    fireEvent.click(screen.getByTestId('section-Heaters'));
    const sel = screen.getByTestId('field-Heaters$HEATER_1$Control method') as HTMLSelectElement;
    expect(sel.value).toBe('PID');
    expect(screen.getByTestId('field-Heaters$HEATER_1$Control method$PID$Proportional scale')).toBeTruthy();
    fireEvent.change(sel, { target: { value: 'Bang bang' } });
    expect(screen.queryByTestId('field-Heaters$HEATER_1$Control method$PID$Proportional scale')).toBeNull();
    fireEvent.change(screen.getByTestId('field-Heaters$HEATER_1$Control method') as HTMLSelectElement, {
      target: { value: 'PID' },
    });
    expect(
      (screen.getByTestId('field-Heaters$HEATER_1$Control method$PID$Proportional scale') as HTMLInputElement)
        .value,
    ).toBe('0.0871');
  });

  it('shows server errors under the field or group their Key points at', () => {
    const { pf, model } = board3();
    model.setServerErrors(
      placeErrors(pf, configValuesSchema.parse(json('config-post-schema-error.json')).Errors),
    );
    render(<FormView model={model} assetBase="/machines/p1" />);
    expect(screen.getByTestId('section-Kinematics').textContent).toContain('2');
    fireEvent.click(screen.getByTestId('section-Kinematics'));
    expect(screen.getByTestId('server-error-Kinematics').textContent).toMatch(
      /Key is not a recognised parameter name/,
    );
    expect(screen.getByTestId('server-error-Kinematics$Maximum acceleration').textContent).toMatch(
      /must not be less than 1.00000000000000E-06/,
    );
  });

  it('search finds names and descriptions and opens the field', () => {
    const { model } = board3();
    render(<FormView model={model} assetBase="/machines/p1" />);
    fireEvent.change(screen.getByLabelText('Search settings'), { target: { value: 'IRUN during homing' } });
    const results = screen.getByTestId('form-search-results');
    expect(within(results).getAllByText(/STEPPER_\d › IRUN during homing/).length).toBe(6);
  });

  it('the review dialog lists every change old → new', () => {
    const { model } = board3();
    act(() => {
      model.set('Steppers$STEPPER_1$Run current', '2');
      model.set('Fans$FAN_1$Invert PWM output', true);
    });
    render(<ReviewChanges model={model} onCancel={() => undefined} actions={null} />);
    const rows = screen.getByTestId('review-table').querySelectorAll('tbody tr');
    expect([...rows].map((r) => r.textContent)).toEqual([
      'Steppers › STEPPER_1 › Run current1.22 amp',
      'Fans › FAN_1 › Invert PWM outputoffon',
    ]);
  });

  it('renders board documentation sanitized, with the image through the machine prefix', () => {
    const { model } = board3();
    render(<FormView model={model} assetBase="/machines/p1" />);
    fireEvent.click(screen.getByTestId('section-Steppers'));
    const group = screen.getByTestId('group-Steppers$STEPPER_1');
    fireEvent.click(within(group).getAllByText('Help')[0] as HTMLElement);
    const img = group.querySelector('.fm-desc-body img');
    expect(img?.getAttribute('src')).toBe('/machines/p1/extras/images/stepper_1.png');
  });
});
