import { createContext, useContext } from 'react';
import { useStore } from 'zustand';
import type { FormModel } from './model';

/**
 * The form's context: its value never changes for a form, so it causes no re-renders. Every
 * component of the form reads the model from it and selects only the slice it shows.
 */
export interface FormCtx {
  model: FormModel;
  assetBase: string;
  readOnly: boolean;
}

export const FormContext = createContext<FormCtx | null>(null);

export function useForm(): FormCtx {
  const c = useContext(FormContext);
  if (!c) throw new Error('FormView context missing');
  return c;
}

/** Whether a node is shown (FormModel.isActive), re-rendering only when that changes. */
export function useActive(id: string): boolean {
  const { model } = useForm();
  return useStore(model.store, (s) => model.isActive(id, s));
}
